"""Request ids go on across restarts of a namespace's supervisor: no two bags share one.

The supervisor keeps the last id it gave beside the namespace's name claim; a restarted one
numbers its requests on from there. The graph is restarted (a new process would read the same
file), one grasp is recorded before and one after, and the bags' statuses and commands are read.
"""
from __future__ import annotations

import os

from gripper_ros.bags.series import load_grasp_series
from gripper_ros.nodes.graph import GraphOptions, GripperGraph
from gripper_ros.nodes.names import claim_folder, GRASP_ID_FILE
from gripper_ros.nodes.recording import recorded_grasp
from gripper_ros.studies.paper import PAPER_OBJECTS
from gripper_ros.wire import DEFAULT_NAMESPACE
import numpy as np
import pytest

WIDTH_M, MASS_KG = PAPER_OBJECTS[0]


@pytest.fixture
def claims(tmp_path, monkeypatch):
    """Give the test a claims folder of its own, so that earlier runs' ids do not count."""
    monkeypatch.setenv('GRIPPER_ROS_CLAIMS_DIR', str(tmp_path / 'claims'))
    return tmp_path / 'claims'


def _grasp_in_a_new_graph(bag_dir, namespace: str = DEFAULT_NAMESPACE):
    with GripperGraph.in_own_context(GraphOptions(namespace=namespace)) as graph:
        run = recorded_grasp(graph, bag_dir, WIDTH_M, MASS_KG)
    assert run.response.success, run.response.message
    return run


def _ids_in(bag_dir) -> set[int]:
    series = load_grasp_series(bag_dir)
    ids = np.concatenate((series.decisions['grasp_id'], series.commands['grasp_id']))
    return set(np.unique(ids[ids > 0]).tolist())


def test_a_restarted_supervisor_numbers_its_grasps_on(claims, tmp_path):
    first = _grasp_in_a_new_graph(tmp_path / 'before')
    second = _grasp_in_a_new_graph(tmp_path / 'after')
    assert second.response.grasp_id == first.response.grasp_id + 1
    assert _ids_in(first.bag_dir) == {first.response.grasp_id}
    assert _ids_in(second.bag_dir) == {second.response.grasp_id}


def test_each_namespace_counts_its_own_and_an_unreadable_record_starts_at_one(claims, tmp_path):
    _grasp_in_a_new_graph(tmp_path / 'a')
    # a damaged record must not stop the gripper: it numbers from 1 again
    record = claim_folder(int(os.environ['ROS_DOMAIN_ID']), DEFAULT_NAMESPACE) / GRASP_ID_FILE
    assert record.read_text(encoding='ascii').strip() == '1'
    record.write_text('not a number\n', encoding='ascii')
    assert _grasp_in_a_new_graph(tmp_path / 'b').response.grasp_id == 1
    assert _grasp_in_a_new_graph(tmp_path / 'c', 'other').response.grasp_id == 1

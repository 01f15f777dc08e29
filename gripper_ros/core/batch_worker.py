"""Imported by the fork server of the batch engine (:func:`gripper_ros.core.headless.map_cases`).

The fork server forks every worker process of a batch. Importing this module there loads the
compiled core from numba's cache (and the DMC models of the default configuration) once, by
running one short grasp, so that each worker starts with it in memory: a worker that loaded it
itself would pay about a second before its first grasp, a large share of a short batch.
"""
from gripper_ros.core.headless import warm_up_worker

warm_up_worker()

"""position_controller: MPC-PD (DMC over PD, Table II) for the position stage, every 10 ms.

Answers each ``loop/position_reference`` (the ticks on which the supervisor names the position
stage: approaching an object, releasing, holding the fingers still) with the armature voltage
for the next ``sample_time_s``. ``controller`` selects ``mpc_pd`` (default), ``pd`` or ``pid``.
"""
from __future__ import annotations

import sys

from gripper_ros.core.control.stages import PositionStageController
from gripper_ros.nodes.controller_node import LockstepController
from gripper_ros.nodes.parameters import declare_controller
from gripper_ros.nodes.process import run_node
from gripper_ros.wire import (Controller, DEFAULT_POSITION_CONTROLLER, NODE_POSITION_CONTROLLER,
                              PositionControllerKind)


class PositionControllerNode(LockstepController, stage=Controller.POSITION,
                             section='position_control'):
    def declare_stage_parameters(self) -> None:
        self.kind = declare_controller(self, PositionControllerKind, DEFAULT_POSITION_CONTROLLER)

    def build_stage(self, config) -> PositionStageController:
        return PositionStageController(config, self.kind)


def main(args=None):
    return run_node(PositionControllerNode, NODE_POSITION_CONTROLLER, args)


if __name__ == '__main__':
    sys.exit(main())

"""force_controller: the force stage, every force sample (0.1 ms), from contact to the hold.

The default law is the contact-aware stage (:mod:`gripper_ros.core.control.contact_force`:
feed-forward, a speed-shaped approach, force feedback with stiffness-scheduled damping), for rigid
and compliant objects alike; ``controller`` selects the paper's ``pi`` or ``mpc_pi`` instead, whose
output is capped before contact at ``approach_force_margin`` x the stall voltage of the setpoint
(eq. 13). It answers each ``loop/force_reference`` and keeps holding after the grasp is answered
HOLDING, until the supervisor names another stage.
"""
from __future__ import annotations

import sys

from gripper_ros.core.control.stages import ForceStageController
from gripper_ros.nodes.controller_node import LockstepController
from gripper_ros.nodes.parameters import declare_controller
from gripper_ros.nodes.process import run_node
from gripper_ros.wire import (Controller, DEFAULT_APPROACH_FORCE_MARGIN, DEFAULT_FORCE_CONTROLLER,
                              ForceControllerKind, NODE_FORCE_CONTROLLER)
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor


class ForceControllerNode(LockstepController, stage=Controller.FORCE, section='force_control'):
    def declare_stage_parameters(self) -> None:
        self.kind = declare_controller(
            self, ForceControllerKind, DEFAULT_FORCE_CONTROLLER,
            "contact_aware (default: rigid and compliant objects) | pi | mpc_pi (the paper's "
            'structure)')
        self.approach_margin = self.declare_parameter(
            'approach_force_margin', DEFAULT_APPROACH_FORCE_MARGIN, ParameterDescriptor(
                description='pi / mpc_pi: cap before contact, margin x stall voltage of the '
                            'force setpoint; 0 disables the cap (the paper behaviour). '
                            'contact_aware caps its approach itself',
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=10.0)])).value
        self.add_post_set_parameters_callback(self._on_parameters_set)

    def build_stage(self, config) -> ForceStageController:
        return ForceStageController(config, self.kind, self.approach_margin)

    def _on_config_change(self, config, keys, stage) -> None:
        """Gains and margin changed together: the stage the check built has the old margin."""
        if stage.approach_margin != self.approach_margin:
            stage = self.build_stage(config)
        super()._on_config_change(config, keys, stage)

    def _on_parameters_set(self, parameters) -> None:
        """Build the stage of an accepted ``approach_force_margin``: in use from the next stage.

        Never mid-stage (the kernel's record keeps the margin it was built with); the
        descriptor's range refuses the rest.
        """
        for p in parameters:
            if p.name == 'approach_force_margin':
                self.approach_margin = float(p.value)
                self._next_stage = self.build_stage(self.config)


def main(args=None):
    return run_node(ForceControllerNode, NODE_FORCE_CONTROLLER, args)


if __name__ == '__main__':
    sys.exit(main())

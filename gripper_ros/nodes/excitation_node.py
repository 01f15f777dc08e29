"""excitation_server: the identification experiment as a service beside ``move``.

``excite`` (std_srvs/Trigger) runs :class:`gripper_ros.identify.excitation.ExcitationRun` over
the graph's ``move`` and ``grasp`` services: the node's parameters ``excitation.seconds``,
``.amplitude_v``, ``.seed`` and ``.hold`` say how long, how hard and which sequence (a bad value
is refused with the reason and nothing changes). ``stop`` ends the running request STOPPED and
with it the experiment; the answer says how it ended. The simulated time comes from
``supervisor/status``. Against hardware that serves the same ``move``, ``grasp`` and status, it
runs the same. Recording is the recorder's (``grasp_demo --serve`` records each move);
``excite`` the console app records the whole experiment in one bag.
"""
from __future__ import annotations

import sys

from gripper_interfaces.msg import SupervisorStatus
from gripper_interfaces.srv import Grasp, Move
from gripper_ros.core.supervision.requests import GraspRequest
from gripper_ros.identify.excitation import check_spec, ExcitationRun, ExcitationSpec
from gripper_ros.nodes.gripper_node import GripperNode
from gripper_ros.nodes.loop_io import read_status
from gripper_ros.nodes.parameters import declare_config
from gripper_ros.nodes.process import run_node
from gripper_ros.nodes.qos import SERVICE_QOS
from gripper_ros.nodes.services import DeferredService
from gripper_ros.nodes.startup import StartupError
from gripper_ros.wire import (NODE_EXCITATION, Outcome, SERVICE_EXCITE, SERVICE_GRASP,
                              SERVICE_MOVE, stamp_ns, TOPIC_STATUS)
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from std_srvs.srv import Trigger

PARAMETER_PREFIX = 'excitation.'


class ExcitationServer(GripperNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_EXCITATION, **kwargs)
        self.config = declare_config(self)
        d = ExcitationSpec()
        for name, value, what in (('seconds', d.seconds, 'simulated duration (s)'),
                                  ('amplitude_v', d.amplitude_v, 'most driving voltage (V)'),
                                  ('seed', d.seed, 'seed of the pseudo-random sequence'),
                                  ('hold', d.hold, 'also grasp a rigid stop (force model, L/R)')):
            self.declare_parameter(PARAMETER_PREFIX + name, value,
                                   ParameterDescriptor(description=what))
        try:
            self.spec = check_spec(self._spec_with({}), self.config.plant)
        except ValueError as exc:          # check_spec's message starts with the field's name
            raise StartupError(PARAMETER_PREFIX + str(exc)) from None
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._move = self.create_client(Move, SERVICE_MOVE, qos_profile=SERVICE_QOS)
        self._grasp = self.create_client(Grasp, SERVICE_GRASP, qos_profile=SERVICE_QOS)
        self.graph_subscription(SupervisorStatus, TOPIC_STATUS, self._on_status)
        self._now_ns: int | None = None
        self._run: ExcitationRun | None = None      # the experiment running
        self._header = None                         # whom to answer when it ends
        self._service = DeferredService(self, Trigger, SERVICE_EXCITE, self._excite)

    def _spec_with(self, changes: dict) -> ExcitationSpec:
        def value(name):
            if name in changes:
                return changes[name]
            return self.get_parameter(PARAMETER_PREFIX + name).value
        return ExcitationSpec(float(value('seconds')), float(value('amplitude_v')),
                              value('seed'), bool(value('hold')))

    def _check_parameters(self, parameters) -> SetParametersResult:
        changes = {p.name[len(PARAMETER_PREFIX):]: p.value for p in parameters
                   if p.name.startswith(PARAMETER_PREFIX)}
        if not changes:
            return SetParametersResult(successful=True)
        try:
            check_spec(self._spec_with(changes), self.config.plant)
        except (TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=PARAMETER_PREFIX + str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters) -> None:
        self.spec = self._spec_with({})

    def _on_status(self, data: bytes) -> None:
        status = read_status(data)
        self._now_ns = stamp_ns(status)

    def _excite(self, request, header) -> None:
        """Start the experiment; answered when it ends (refused while one runs or too early)."""
        refusal = ''
        if self._run is not None:
            refusal = 'refused: an excitation is running'
        elif self._now_ns is None or not self._move.service_is_ready() or (
                self.spec.hold and not self._grasp.service_is_ready()):
            refusal = f'refused: no {TOPIC_STATUS}, {SERVICE_MOVE} or {SERVICE_GRASP} yet'
        if refusal:
            self._service.reply(header, Trigger.Response(success=False, message=refusal))
            return
        self._run, self._header = ExcitationRun(self.spec, self.config, self._now_ns), header
        self._next()

    def _next(self) -> None:
        request = self._run.next_request(self._now_ns)
        if request is None:
            run, header = self._run, self._header
            self._run = self._header = None
            self._service.reply(header, Trigger.Response(success=not run.ended_by,
                                                         message=run.summary(self._now_ns)))
            return
        if isinstance(request, GraspRequest):
            future = self._grasp.call_async(Grasp.Request(
                width_m=request.width_m, mass_kg=request.mass_kg, timeout_s=request.timeout_s))
        else:
            future = self._move.call_async(Move.Request(
                width_m=request.width_m, speed_mps=request.speed_mps,
                max_effort_n=request.max_effort_n, timeout_s=request.timeout_s))
        future.add_done_callback(self._on_answer)

    def _on_answer(self, future) -> None:
        answer = future.result()
        self._run.answered(Outcome(answer.outcome).name, answer.message)
        self._next()


def main(args=None):
    return run_node(ExcitationServer, NODE_EXCITATION, args)


if __name__ == '__main__':
    sys.exit(main())

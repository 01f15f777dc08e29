"""The simulated arm's announcements, without ROS: a lift's plan, once, as its hold begins.

A placement may ask the arm to announce its lift (``SetObject.announce_lift``): when the grasp
that holds the object has begun its hold, the arm publishes the lift's breakpoints
(:meth:`gripper_ros.core.physics.plant.GripperPlant.lift_plan`) on
``arm/planned_acceleration``, once per grasp, as a planning arm would before it moves.
"""
from __future__ import annotations


class LiftAnnouncer:
    """Whether the lift's plan is due now: asked for, its hold begun, not yet announced."""

    def __init__(self) -> None:
        self.armed = False
        self.announced_for = -1         # the grasp whose lift was announced
        self.announced = 0              # plans announced

    def arm(self, announce: bool, hold_begun_for: int) -> None:
        """Take a new placement (``announce``: its lift is to be announced)."""
        self.armed = announce
        self.announced_for = hold_begun_for

    def due(self, hold_begun_for: int) -> bool:
        """Say whether to announce now: the hold of grasp ``hold_begun_for`` (-1: none) began.

        True once per grasp; counted as announced.
        """
        if not self.armed or hold_begun_for == self.announced_for or hold_begun_for < 0:
            return False
        self.announced_for = hold_begun_for
        self.announced += 1
        return True

"""The paper's published figures: the answers the demos, tables and studies are held against."""
from __future__ import annotations

from gripper_ros.studies.metrics import StepMetrics

PAPER_OBJECTS = ((0.01, 1.27), (0.05, 1.69), (0.10, 0.75))
"""Table V: the three objects grasped, (width m, mass kg)."""

PAPER_TABLE_III = {
    'PD': StepMetrics(0.0242, 7.2985, 4.6404),
    'PID': StepMetrics(0.0390, 0.0469, 10.8165),
    'MPC-PD': StepMetrics(0.0238, 4.7207, 3.1805),
}
"""Table III: the position step (RMS error m, overshoot %, settling time s) per controller."""

PAPER_TABLE_IV = {
    'PI': StepMetrics(0.0888, 2.4345, 3.557e-4),
    'MPC-PI': StepMetrics(0.0360, 8.8266, 0.0011),
}
"""Table IV: the force step (RMS error N, overshoot %, settling time s) per controller."""

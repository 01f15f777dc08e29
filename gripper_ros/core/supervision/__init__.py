"""Grasp and move requests and the supervisor state machine."""

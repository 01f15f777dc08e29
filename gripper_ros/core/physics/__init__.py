"""The physics: plant (motor, screw, contact), held object, sensors."""

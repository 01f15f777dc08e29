"""Studies over the core: step, grip, lift and sweep runs, the position floor, the paper's figures.

No rclpy: the console programs in apps/ print and draw what these compute.
"""

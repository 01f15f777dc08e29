"""The control laws, the stage controllers and their factories."""

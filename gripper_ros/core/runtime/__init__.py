"""One lockstep tick, the compiled loop and the batch engine."""

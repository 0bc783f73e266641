"""The use cases: steps, run, calibrate, batch, gait forms; each ties the algorithm packages together."""

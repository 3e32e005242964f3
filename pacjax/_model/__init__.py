"""The model: strain fields and kinematics, the body, tendons and loads, their energies, and the
scene that assembles them (with its structured derivatives). Imports nothing above it."""

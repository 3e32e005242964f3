"""Dynamics: damping of the body and the motors, and time integration of the paper's eq. 7."""

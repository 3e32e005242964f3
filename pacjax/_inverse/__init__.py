"""Inverse statics: the command least-squares problem, its solves and their results."""

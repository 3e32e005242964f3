"""Static equilibria: the scaled problem, pseudo-transient continuation, retries, single and
batched solves, the slot pool, several equilibria of one scene."""

"""The executor's states: each a named unit whose `tick` answers a Command or the next state."""

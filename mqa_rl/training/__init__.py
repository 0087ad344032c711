"""State of a DQN training run that survives a kill: the checkpoint."""

"""DQN loss and prioritized replay for the push Q-network."""

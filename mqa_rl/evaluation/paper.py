"""The paper's reported numbers (Deng et al., RSS 2021, arXiv 2003.04641), to print beside ours."""

# Table III: COUNTING accuracy on the test split per level, by manipulation policy.
TABLE_III = {
    "random": {"easy": 0.2771, "medium": 0.3079, "hard": 0.2735},
    "dqn_global": {"easy": 0.4767, "medium": 0.3939, "hard": 0.3388},
    "dqn_local": {"easy": 0.4458, "medium": 0.4242, "hard": 0.5289},
    "dqn_global_local": {"easy": 0.4536, "medium": 0.4130, "hard": 0.3838},
}
# the paper's names of our systems
PAPER_NAMES = {"random": "random", "dqn_global": "DQN(R_g)", "dqn_local": "DQN(R_l)", "dqn_global_local": "DQN(R_g+R_l)",
               "dqfd_global": "DQfD(R_g)", "dqfd_local": "DQfD(R_l)", "dqfd_global_local": "DQfD(R_g+R_l)"}

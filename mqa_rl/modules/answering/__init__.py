"""The answering half: what answers the question from the frames an episode leaves.

``vqa`` is the answering model (EmbodiedQA's VQA over I_start and I_stop, or heads over the counting perception's
counts), ``vqa_encoder`` EmbodiedQA's small CNN and the heads that pretrain it, ``vqa_ensemble`` several seeds of one
system answering as one. ``perception`` is the counting perception (a U-Net trained on the simulator's labels) and
``vote_counting`` the counts read off its class probabilities, centre votes and density. ``perceived_count`` is that
perception's reading of the asked class in a state (what a learned stop in ``modules.stop`` reads, and the keeper), and
``kept_frame`` chooses which frame of an episode the answer reads as I_stop."""

"""The push policy: the paper's manipulation Q-network and the policies that push.

``push_qnet`` is the Q-network (Sec. IV-B: rgb and depth through a visual trunk, the question through an LSTM, a Q map
per push direction and a stop map), built from ``trunks`` (the ResNet cuts, the light stack, EfficientNet-Lite0) and
``rotated_head`` (one push head shared by the eight directions); ``imagenet_backbone`` is the ImageNet-pretrained
EfficientNet-Lite0 encoder behind the ``efficientnet_lite0`` trunk, which the counting perception
(``modules.answering.perception``) reads too, as the VQA reads this network's question encoder.
``pretrained_recognition`` is the network's pretrained recognition as a file that DQN training starts from.
``push_policy`` wraps the network as TorchRL's greedy ``QValueActor`` and its ε-greedy explorer, and ``trained_policy``
loads a ``recipes/train_dqn.py`` run as that greedy actor. Beside it, the policies that do not learn: ``random_policy``
(the paper's random baseline) and ``privileged_policy`` (the oracle that reads the simulator). How a greedy policy's
stop is overruled is in ``modules.stop``."""

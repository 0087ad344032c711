"""Policies and networks (TorchRL modules), in three parts: ``push`` (the paper's Q-network and the policies that push),
``stop`` (when a policy stops pushing) and ``answering`` (the VQA, the counting perception and the frame the answer
reads). Over them, ``frozen_policies`` builds a system's policy from its spec and ``systems`` looks systems up by id in
the registry (``recipes/conf/systems.yaml``)."""

"""Policies and networks (TorchRL modules)."""

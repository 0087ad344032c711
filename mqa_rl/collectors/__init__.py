"""Collectors that run the MQA env (with its reward stack) in worker processes."""

"""The MQA dataset: object library, settled bin scenes, template questions with oracle answers.

``generate_dataset`` and ``MQADataset`` are imported lazily so that ``import mqa_rl.data`` stays
cheap (SAPIEN is only imported when scenes are settled).
"""

__all__ = ["generate_dataset", "MQADataset", "DatasetError"]


def __getattr__(name):
    if name in ("generate_dataset", "MQADataset"):
        from mqa_rl.data import dataset

        return getattr(dataset, name)
    if name == "DatasetError":
        from mqa_rl.data.storage import DatasetError

        return DatasetError
    raise AttributeError(f"module 'mqa_rl.data' has no attribute {name!r}")

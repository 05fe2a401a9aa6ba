"""LeRobotDataset v3.0 (Hugging Face's imitation-learning format) with pyarrow and PyAV, no lerobot or torch.

* ``dataset``: the layout, ``write_dataset``/``append_episodes`` and the readers (``read_actions``, ...);
* ``stats``: the per-episode and dataset stats as lerobot computes them;
* ``video``: encoding (AV1, lerobot's defaults), joining and cutting episodes' videos.
"""

"""Write a dataset's frames again with lerobot's own writer, for its layout (not a test module: tests/test_datagen.py runs it).

    PYTHON tests/lerobot_write.py DATASET OUT

Run by the Python of an environment where lerobot is installed (as ``tests/lerobot_read.py``), importing nothing
of roarmctl: the frames of DATASET (its parquet rows and its videos decoded with PyAV) go through
``LeRobotDataset.create`` (the same features, fps and robot type, h264), ``add_frame`` and ``save_episode``
episode by episode, then ``finalize``, into OUT; prints lerobot's version as JSON.
"""

from __future__ import annotations

import json
import sys
from importlib.metadata import version
from pathlib import Path


def main() -> int:
    import av
    import numpy as np
    import pyarrow.parquet as pq
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    info = json.loads((src / "meta/info.json").read_text())
    default = ("timestamp", "frame_index", "episode_index", "index", "task_index")
    features = {k: {"dtype": v["dtype"], "shape": tuple(v["shape"]), "names": v["names"]}
                for k, v in info["features"].items() if k not in default}
    ds = LeRobotDataset.create("local/lerobot_written", fps=info["fps"], features=features, root=dst,
                               robot_type=info["robot_type"], use_videos=True, vcodec="h264")
    data = pq.read_table(src / "data").sort_by("index").to_pydict()
    tasks = pq.read_table(src / "meta/tasks.parquet").to_pandas()
    images = {}
    for key, f in features.items():
        if f["dtype"] == "video":
            with av.open(str(src / "videos" / key / "chunk-000" / "file-000.mp4")) as v:
                images[key] = [frame.to_ndarray(format="rgb24") for frame in v.decode(video=0)]
    n = len(data["index"])
    for i in range(n):
        frame = {"task": tasks.index[data["task_index"][i]]}
        for key in features:
            frame[key] = images[key][i] if key in images else np.array(data[key][i], dtype=np.float32)
        ds.add_frame(frame)
        if i == n - 1 or data["episode_index"][i + 1] != data["episode_index"][i]:
            ds.save_episode()
    ds.finalize()
    json.dump({"lerobot": version("lerobot")}, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())

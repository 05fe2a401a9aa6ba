"""The videos of a LeRobot dataset, with PyAV: encode frames, join episodes, cut one out, probe, decode.

Two encoders, both among lerobot's ``VideoEncoderConfig`` codecs (huggingface/lerobot
``src/lerobot/configs/video.py``), ``yuv420p`` with a key frame every 2 frames (``g``, lerobot's default, so any
frame decodes quickly) and one encoder thread, so that the same frames give the same bytes on any machine load:

* ``h264`` (the default here): x264, preset ``ultrafast``, ``crf`` 23: 0.6-0.7 ms of CPU a 320x240 frame;
* ``av1`` (lerobot's default): SVT-AV1, preset 12, ``crf`` 30 (lerobot's settings), ``lp=1``: 4-6 ms a frame
  (bench/bench_datagen.py), files about 0.6 times the size.

An episode's video is encoded once (by the worker that rendered it); a dataset's file joins the episodes'
packets without decoding them again (a remux), each episode shifted to start where the previous one ends,
as lerobot's ``concatenate_video_files`` does, so that ``from_timestamp``/``to_timestamp`` in the
episodes' metadata are the frame counts before and after it divided by the fps.
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator, Sequence
from fractions import Fraction
from typing import Any

import numpy as np

PIX_FMT = "yuv420p"
#: codec -> (FFmpeg encoder, the settings written as video.* in info.json, as lerobot records its encoder's)
CODECS: dict[str, tuple[str, dict[str, Any]]] = {
    "h264": ("libx264", {"g": 2, "crf": 23, "preset": "ultrafast"}),
    "av1": ("libsvtav1", {"g": 2, "crf": 30, "preset": 12, "fast_decode": 0}),
}


@contextlib.contextmanager
def _scheduling_kept() -> Iterator[None]:
    """Run the block without the right to real-time scheduling, and give the calling thread back the scheduling
    policy and priority it had before it.

    SVT-AV1 starts its threads with the real-time policy SCHED_FIFO at priority 99 whenever it is allowed to
    (``svt_create_thread``, Source/Lib/Common/Codec/EbThreads.c in AOMediaCodec/SVT-AV1): as root it is, and its
    busy encoder threads then own their cores while they run. Where that right is refused (``EPERM``) it creates
    them under the normal policy, so the block runs with CAP_SYS_NICE out of this thread's *effective*
    capabilities (``capabilities(7)``: per thread, inherited by the threads it creates; it stays in the permitted
    set and comes back after). Measured with the libsvtav1 PyAV ships, as root: without this, the encoder's threads
    were SCHED_FIFO 99 during the encode and the *calling* thread stayed so afterwards, and every process it
    started inherited it (in a clean-clone CI run a busy-loop child starved a planner on the same core so
    completely that it could not even be killed, and the run hung until its time limit)."""
    if not hasattr(os, "sched_getscheduler"):  # not Linux: no such policy change
        yield
        return
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    with _without_sys_nice():
        try:
            yield
        finally:
            if os.sched_getscheduler(0) != policy or os.sched_getparam(0) != param:
                os.sched_setscheduler(0, policy, param)  # lowering a priority is always allowed


@contextlib.contextmanager
def _without_sys_nice() -> Iterator[None]:
    """CAP_SYS_NICE out of the calling thread's effective capabilities for the block, if it had it (pyprctl)."""
    import pyprctl

    had = pyprctl.Cap.SYS_NICE in pyprctl.CapState.get_current().effective
    if had:
        pyprctl.cap_effective.drop(pyprctl.Cap.SYS_NICE)
    try:
        yield
    finally:
        if had:
            pyprctl.cap_effective.add(pyprctl.Cap.SYS_NICE)


def encode(frames: np.ndarray, fps: int, codec: str = "h264") -> bytes:
    """MP4 bytes of ``frames`` (F, height, width, 3) uint8 RGB at ``fps`` in ``codec`` (``CODECS``); frame k at k / fps s."""
    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1's own log (its banner on stderr for every video): errors only
    # SVT-AV1 (below) is the encoder that asks for real-time threads; x264 runs as it is
    with _scheduling_kept() if CODECS[codec][0] == "libsvtav1" else contextlib.nullcontext():
        return _encode(np.ascontiguousarray(frames, dtype=np.uint8), fps, codec)


def _encode(frames: np.ndarray, fps: int, codec: str) -> bytes:
    import av

    n, h, w, _ = frames.shape
    buf = io.BytesIO()
    with av.open(buf, "w", format="mp4") as out:
        name, settings = CODECS[codec]
        opts = {k: str(settings[k]) for k in ("g", "crf", "preset")}
        if name == "libsvtav1":
            opts["svtav1-params"] = f"fast-decode={settings['fast_decode']}:lp=1"
        stream: Any = out.add_stream(name, rate=fps, options=opts)
        if name == "libx264":
            stream.codec_context.thread_count = 1
        stream.width, stream.height, stream.pix_fmt = w, h, PIX_FMT
        stream.time_base = Fraction(1, fps)
        for k in range(n):
            frame = av.VideoFrame.from_ndarray(frames[k], format="rgb24")
            frame.pts = k
            frame.time_base = Fraction(1, fps)
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    return buf.getvalue()


class Joiner:
    """One MP4 written to ``out`` (a path or a binary file) from episodes' MP4s (as ``encode`` makes them) added
    one after the other, packets copied, not decoded; ``close()`` finishes the file."""

    def __init__(self, out: Any, fps: int) -> None:
        import av

        self.fps = fps
        self._av = av
        self.dst: Any = av.open(str(out) if isinstance(out, os.PathLike) else out, "w", format="mp4")
        self.stream: Any = None
        self.offset = 0  # frames before the next part

    def add(self, data: bytes, frames: int) -> None:
        """Append one episode's MP4 bytes (``frames`` frames), shifted to start where the previous one ends."""
        with self._av.open(io.BytesIO(data), "r") as src:
            s = src.streams.video[0]
            if self.stream is None:
                self.stream = self.dst.add_stream_from_template(s, opaque=True)
                self.stream.time_base = Fraction(1, self.fps)
            for packet in src.demux(s):
                if packet.dts is None:
                    continue
                scale = Fraction(packet.time_base) * self.fps
                packet.pts = int(round(packet.pts * scale)) + self.offset if packet.pts is not None else None
                packet.dts = int(round(packet.dts * scale)) + self.offset
                packet.duration = int(round(packet.duration * scale)) if packet.duration else 1
                packet.time_base = Fraction(1, self.fps)
                packet.stream = self.stream
                self.dst.mux(packet)
        self.offset += int(frames)

    def close(self) -> None:
        """Finish the file (its index written)."""
        self.dst.close()


def join(parts: Sequence[bytes], frames: Sequence[int], fps: int, out: Any) -> None:
    """Write one MP4 to ``out`` (a path or a binary file) holding the episodes ``parts`` (MP4 bytes, as
    ``encode`` makes them, ``frames[i]`` frames each) one after the other (``Joiner``)."""
    joiner = Joiner(out, fps)
    try:
        for data, n in zip(parts, frames):
            joiner.add(data, n)
    finally:
        joiner.close()


def cut(path: Any, start: int, count: int, fps: int) -> bytes:
    """The MP4 bytes of frames ``start`` .. ``start + count - 1`` of a dataset's video file (an episode),
    packets copied and shifted to start at 0 (every episode starts on a key frame: ``join``)."""
    import av

    buf = io.BytesIO()
    with av.open(path, "r") as src, av.open(buf, "w", format="mp4") as dst:
        s = src.streams.video[0]
        stream = dst.add_stream_from_template(s, opaque=True)
        stream.time_base = Fraction(1, fps)
        for packet in src.demux(s):
            if packet.dts is None or packet.pts is None:
                continue
            scale = Fraction(packet.time_base) * fps
            k = int(round(packet.pts * scale))
            if not start <= k < start + count:
                continue
            packet.pts = k - start
            packet.dts = int(round(packet.dts * scale)) - start
            packet.duration = int(round(packet.duration * scale)) if packet.duration else 1
            packet.time_base = Fraction(1, fps)
            packet.stream = stream
            dst.mux(packet)
    return buf.getvalue()


def probe(path: Any) -> dict[str, Any]:
    """The ``info`` of a video feature in ``meta/info.json`` as lerobot's ``get_video_info`` writes it."""
    import av

    with av.open(path, "r") as f:
        s = f.streams.video[0]
        info: dict[str, Any] = {"video.height": s.height, "video.width": s.width, "video.codec": s.codec_context.codec.canonical_name
                                if hasattr(s.codec_context.codec, "canonical_name") else s.codec_context.name,
                                "video.pix_fmt": s.pix_fmt, "video.is_depth_map": False,
                                "video.fps": int(s.base_rate) if s.base_rate else None, "video.channels": 3,
                                "has_audio": bool(f.streams.audio)}
    info.update({f"video.{k}": v for k, v in CODECS.get(info["video.codec"], ("", {}))[1].items()})
    # video.is_depth_map as lerobot 0.4.4's get_video_info writes it; the encoder's settings and is_depth_map, as
    # later lerobot records them, beside it
    info |= {"video.video_backend": "pyav", "video.extra_options": {}, "is_depth_map": False}
    return info


def decode(path: Any) -> tuple[np.ndarray, np.ndarray]:
    """Every frame of a video (F, height, width, 3) uint8 RGB and its time (F,) s."""
    import av

    frames, times = [], []
    with av.open(path, "r") as f:
        for frame in f.decode(video=0):
            frames.append(frame.to_ndarray(format="rgb24"))
            times.append(float(frame.time) if frame.time is not None else float("nan"))
    return np.array(frames, dtype=np.uint8).reshape(len(frames), *(frames[0].shape if frames else (0, 0, 3))), np.array(times)

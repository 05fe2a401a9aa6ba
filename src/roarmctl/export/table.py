"""CSV export for spreadsheets: one row per sample with time, joints, TCP position and speed."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from roarmctl.export.streams import Streams
from roarmctl.fileio import atomic_write_text


def csv_text(streams: Streams) -> str:
    """The CSV of ``streams``: columns ``source`` (plan / commanded / measured), ``time_s``, one
    ``<joint>_rad`` per joint (``<joint>_m`` for a prismatic one), ``<joint>_rad_s`` (``_m_s``) per
    joint when velocities are known, ``tcp_x_m``,
    ``tcp_y_m``, ``tcp_z_m`` (FK of the joints) and ``tcp_speed_m_s`` (|J_v(q) qdot| when
    velocities are known, else the finite difference of the TCP positions). Rows sorted by source
    then time."""
    robot, names = streams.robot, streams.joint_names
    has_vel = any(s.velocities is not None for s in streams.joint_states.values())
    unit = ["m" if p else "rad" for p in robot.prismatic]  # a prismatic joint in metres
    header = ["source", "time_s"] + [f"{n}_{u}" for n, u in zip(names, unit, strict=True)]
    if has_vel:
        header += [f"{n}_{u}_s" for n, u in zip(names, unit, strict=True)]
    header += ["tcp_x_m", "tcp_y_m", "tcp_z_m", "tcp_speed_m_s"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for key, st in streams.joint_states.items():
        if not len(st.times):
            continue
        q = st.positions
        tcp = robot.kin.fk(q)[:, :3, 3]
        if st.velocities is not None:
            speed = np.linalg.norm(robot.kin.tcp_velocity(q, st.velocities[:, robot.arm_indices]), axis=1)
        else:
            speed = np.zeros(len(st.times))
            if len(st.times) > 1:
                dt = np.diff(st.times)
                step = np.linalg.norm(np.diff(tcp, axis=0), axis=1)
                speed[1:] = np.divide(step, dt, out=np.zeros_like(step), where=dt > 0)
        for i, t in enumerate(st.times):
            row = [key or "plan", f"{t:.6f}"] + [f"{v:.9g}" for v in q[i]]
            if has_vel:
                row += [f"{v:.9g}" for v in st.velocities[i]] if st.velocities is not None else [""] * len(names)
            row += [f"{v:.9g}" for v in tcp[i]] + [f"{speed[i]:.9g}"]
            w.writerow(row)
    return buf.getvalue()


def write_csv(streams: Streams, path: str | os.PathLike) -> Path:
    """Write ``csv_text(streams)`` atomically to ``path``."""
    return atomic_write_text(path, csv_text(streams))

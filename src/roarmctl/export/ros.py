"""ROS 2 messages in an MCAP file or a ROS 2 bag folder, written with ``rosbags``.

Topics (ROS 2 Jazzy message definitions, CDR-serialised, so Foxglove Studio, RViz via
``ros2 bag play`` and any MCAP reader open them):

=================================  =================================  ==========================================
topic                              type                               when
=================================  =================================  ==========================================
``/joint_trajectory``              trajectory_msgs/msg/JointTrajectory  once, at t = 0 (plan only)
``/joint_states``                  sensor_msgs/msg/JointState           every sample (plan: 100 Hz)
``/joint_states/commanded``        sensor_msgs/msg/JointState           every joint command sent (log only)
``/joint_states/measured``         sensor_msgs/msg/JointState           every feedback received (log only)
``/tf``                            tf2_msgs/msg/TFMessage               every sample of the states drawn
                                                                         (plan; log: measured): moving joints
``/tf_static``                     tf2_msgs/msg/TFMessage               once: fixed joints (TCP frame included)
``/scene``                         visualization_msgs/msg/MarkerArray   at t = 0, then at each sample while an
                                                                         object is carried (plan only)
=================================  =================================  ==========================================

Each JointState names every movable joint of the description: the actuated ones (rad, or m for a
prismatic joint), then each mimic joint (its leader's value x multiplier + offset) and each joint held
still (its held value), so a URDF viewer places every link.

Message times: the log time and ``header.stamp`` are the sample time in s from the start of the
trajectory. An execution log's streams are all on its clock, the run's own time (s after the stream's start,
pauses included): a command when it was sent, a measured state when the firmware read the servos
(``device.protocol.frame_read_time``, the log's ``read_t``), a planned sample when the plan, paused for a late host,
reached it; the bag starts at the earliest of them (``time_offset``: added to every log time, so nothing is
negative).
"""

from __future__ import annotations

import functools
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import InputError
from roarmctl.export.streams import Streams
from roarmctl.fileio import (
    check_output_file,
    check_output_folder,
    new_folder_beside,
    note_output_folder,
    replace_folder,
)
from roarmctl.robot.model import quaternions, rigid_inverse

TYPESTORE = "ROS2_JAZZY"
_TF_CHUNK = 1024  # samples whose link transforms are computed together (bounds the memory of a long log's export)
COLORS = {"table": (0.55, 0.45, 0.35, 1.0), "obstacle": (0.85, 0.3, 0.25, 0.8), "object": (0.2, 0.5, 0.9, 1.0)}


@functools.cache
def _typestore() -> Any:
    """rosbags' message types of ROS 2 Jazzy, built once per process: a typestore compiles each message type's
    serialiser on first use, which took as long as an export's messages when every export built a new one."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(getattr(Stores, TYPESTORE))


class _Messages:
    """Builders for the few message types the export writes (rosbags typestore classes)."""

    def __init__(self) -> None:
        self.ts = _typestore()
        t = self.ts.types
        self.Time, self.Duration = t["builtin_interfaces/msg/Time"], t["builtin_interfaces/msg/Duration"]
        self.Header = t["std_msgs/msg/Header"]
        self.JointState = t["sensor_msgs/msg/JointState"]
        self.JointTrajectory, self.Point = t["trajectory_msgs/msg/JointTrajectory"], t["trajectory_msgs/msg/JointTrajectoryPoint"]
        self.TFMessage, self.TransformStamped = t["tf2_msgs/msg/TFMessage"], t["geometry_msgs/msg/TransformStamped"]
        self.Transform, self.Vector3 = t["geometry_msgs/msg/Transform"], t["geometry_msgs/msg/Vector3"]
        self.Quaternion, self.Pose, self.PointMsg = t["geometry_msgs/msg/Quaternion"], t["geometry_msgs/msg/Pose"], t["geometry_msgs/msg/Point"]
        self.Marker, self.MarkerArray = t["visualization_msgs/msg/Marker"], t["visualization_msgs/msg/MarkerArray"]
        self.ColorRGBA, self.MeshFile = t["std_msgs/msg/ColorRGBA"], t["visualization_msgs/msg/MeshFile"]
        self.CompressedImage = t["sensor_msgs/msg/CompressedImage"]

    def stamp(self, ns: int) -> Any:
        return self.Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))

    def duration(self, seconds: float) -> Any:
        ns = int(round(seconds * 1e9))
        return self.Duration(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))

    def header(self, ns: int, frame: str = "") -> Any:
        return self.Header(stamp=self.stamp(ns), frame_id=frame)

    def joint_state(self, ns: int, names: list[str], q: np.ndarray, qd: np.ndarray | None) -> Any:
        empty = np.zeros(0)
        return self.JointState(header=self.header(ns), name=list(names), position=np.asarray(q, dtype=np.float64),
                               velocity=empty if qd is None else np.asarray(qd, dtype=np.float64), effort=empty)

    def trajectory(self, ns: int, frame: str, names: list[str], times: np.ndarray, q: np.ndarray, qd: np.ndarray,
                   qdd: np.ndarray) -> Any:
        pts = [self.Point(positions=np.asarray(q[i], dtype=np.float64), velocities=np.asarray(qd[i], dtype=np.float64),
                          accelerations=np.asarray(qdd[i], dtype=np.float64), effort=np.zeros(0),
                          time_from_start=self.duration(float(times[i]))) for i in range(len(times))]
        return self.JointTrajectory(header=self.header(ns, frame), joint_names=list(names), points=pts)

    def transform(self, ns: int, parent: str, child: str, xyz: Sequence[float], quat: Sequence[float]) -> Any:
        """A TransformStamped of ``child`` in ``parent``: translation ``xyz`` (3 floats, m) and rotation ``quat``
        (4 floats, x y z w; ``robot.model.quaternions``, computed in bulk by the caller)."""
        x, y, z, w = quat
        tr = self.Transform(translation=self.Vector3(x=xyz[0], y=xyz[1], z=xyz[2]),
                            rotation=self.Quaternion(x=x, y=y, z=z, w=w))
        return self.TransformStamped(header=self.header(ns, parent), child_frame_id=child, transform=tr)

    def tf(self, transforms: list) -> Any:
        return self.TFMessage(transforms=transforms)

    def marker(self, ns: int, frame: str, marker_id: int, item: dict[str, Any], pose: np.ndarray,
               quat: Sequence[float]) -> Any:
        """A Marker of a scene item at ``pose`` (4, 4; m) whose rotation is ``quat`` (4 floats; x, y, z, w)."""
        M = self.Marker
        shape = item.get("shape")
        points: list = []
        if shape == "mesh":  # its triangles, item frame (RViz and Foxglove draw a TRIANGLE_LIST in the marker's pose)
            kind, scale = M.TRIANGLE_LIST, [1.0, 1.0, 1.0]
            for piece in item["pieces"]:
                v = np.asarray(piece["vertices"], dtype=float).reshape(-1, 3)
                points += [self.PointMsg(x=float(x), y=float(y), z=float(z))
                           for x, y, z in v[np.asarray(piece["faces"], dtype=np.int64).reshape(-1)]]
        elif shape == "cloud":  # one cube per occupied cell, at its centre (item frame)
            r = float(item["resolution"])
            kind, scale = M.CUBE_LIST, [r, r, r]
            centres = (np.asarray(item["cells"], dtype=float).reshape(-1, 3) + 0.5) * r
            points = [self.PointMsg(x=float(x), y=float(y), z=float(z)) for x, y, z in centres]
        elif shape == "box":
            kind, scale = M.CUBE, [float(v) for v in item["size"]]
        elif shape == "cylinder":
            d = 2.0 * float(item["radius"])
            kind, scale = M.CYLINDER, [d, d, float(item["length"])]
        else:
            d = 2.0 * float(item.get("radius", 0.0))
            kind, scale = M.SPHERE, [d, d, d]
        x, y, z, w = quat
        r, g, b, a = COLORS.get(str(item.get("role")), (0.6, 0.6, 0.6, 1.0))
        return M(header=self.header(ns, frame), ns=str(item.get("role", "scene")), id=marker_id, type=kind, action=M.ADD,
                 pose=self.Pose(position=self.PointMsg(x=float(pose[0, 3]), y=float(pose[1, 3]), z=float(pose[2, 3])),
                                orientation=self.Quaternion(x=x, y=y, z=z, w=w)),
                 scale=self.Vector3(x=scale[0], y=scale[1], z=scale[2]), color=self.ColorRGBA(r=r, g=g, b=b, a=a),
                 lifetime=self.duration(0.0), frame_locked=False, points=points, colors=[], texture_resource="",
                 texture=self.CompressedImage(header=self.header(0), format="", data=np.zeros(0, dtype=np.uint8)),
                 uv_coordinates=[], text=str(item.get("name", "")), mesh_resource="",
                 mesh_file=self.MeshFile(filename="", data=np.zeros(0, dtype=np.uint8)), mesh_use_embedded_materials=False)


def time_offset(streams: Streams) -> float:
    """s added to every time of ``streams`` in a bag: minus the earliest sample of any stream when that is before 0
    (a log's feedback before the motion), else 0. The earliest of all, not each stream's first: a log's measured
    states are stamped when the servos were read, so lines that arrived together can be out of order."""
    return -min(0.0, *(float(np.min(s.times)) for s in streams.joint_states.values() if len(s.times)))


def messages(streams: Streams) -> Iterator[tuple[str, str, int, Any]]:
    """Every message of the export as ``(topic, msgtype, log time ns, message)``, topic by topic; times are the
    streams' plus ``time_offset(streams)``."""
    mk = _Messages()
    robot, names = streams.robot, streams.joint_names
    offset = time_offset(streams)
    ns_of = lambda t: int(round((float(t) + offset) * 1e9))  # noqa: E731
    root = robot.root

    traj = streams.trajectory
    if traj is not None:
        yield ("/joint_trajectory", "trajectory_msgs/msg/JointTrajectory", ns_of(0.0),
               mk.trajectory(ns_of(0.0), root, names, traj.times, traj.positions, traj.velocities, traj.accelerations))
    for suffix, st in streams.joint_states.items():
        topic = "/joint_states" + (f"/{suffix}" if suffix else "")
        # every movable joint of the URDF: the actuated ones, the mimic joints from their leaders and the joints
        # held still, so a URDF viewer (robot_state_publisher, Foxglove) places every link
        all_names, all_q, all_qd = robot.joint_states(st.positions, st.velocities)
        for i, t in enumerate(st.times):
            yield (topic, "sensor_msgs/msg/JointState", ns_of(t),
                   mk.joint_state(ns_of(t), all_names, all_q[i], None if all_qd is None else all_qd[i]))

    kin = robot.kin
    moving = [j for j, joint in enumerate(robot.joints) if joint.kind != "fixed"]
    fixed = [j for j, joint in enumerate(robot.joints) if joint.kind == "fixed"]
    link_names = kin.link_names
    st = streams.joint_states[streams.frames_from]
    if len(st.times):
        def edges(q: np.ndarray, joints: list[int]) -> tuple[list, list]:
            """Child link in parent link for ``joints`` at configurations ``q`` (K, dof): translations (K, J, 3)
            and quaternions (K, J, 4; x y z w), as nested lists of floats."""
            frames = kin.link_frames(q)  # (K, n_links, 4, 4)
            rel = rigid_inverse(frames[:, [kin._parent[j] for j in joints]]) @ frames[:, [kin._child[j] for j in joints]]
            return rel[..., :3, 3].tolist(), quaternions(rel[..., :3, :3]).tolist()

        parents = [link_names[kin._parent[j]] for j in range(len(robot.joints))]
        children = [link_names[kin._child[j]] for j in range(len(robot.joints))]
        if fixed:
            t0 = ns_of(st.times[0])
            xyz, quat = edges(st.positions[:1], fixed)
            yield ("/tf_static", "tf2_msgs/msg/TFMessage", t0,
                   mk.tf([mk.transform(t0, parents[j], children[j], xyz[0][k], quat[0][k]) for k, j in enumerate(fixed)]))
        for start in range(0, len(st.times), _TF_CHUNK):
            xyz, quat = edges(st.positions[start:start + _TF_CHUNK], moving)
            for i, t in enumerate(st.times[start:start + _TF_CHUNK]):
                n = ns_of(t)
                yield ("/tf", "tf2_msgs/msg/TFMessage", n,
                       mk.tf([mk.transform(n, parents[j], children[j], xyz[i][k], quat[i][k]) for k, j in enumerate(moving)]))

    if streams.items:
        # publish the whole scene whenever something in it moved (every carried sample)
        change_times = sorted({float(t) for tr in streams.items for t in tr.times})
        item_quats = [quaternions(np.asarray(tr.poses)[:, :3, :3]).tolist() for tr in streams.items]
        for t in change_times:
            n = ns_of(t)
            markers = []
            for k, (tr, quats) in enumerate(zip(streams.items, item_quats)):
                idx = int(np.searchsorted(tr.times, t + 1e-12, side="right")) - 1
                markers.append(mk.marker(n, root, k, tr.item, tr.poses[max(idx, 0)], quats[max(idx, 0)]))
            yield ("/scene", "visualization_msgs/msg/MarkerArray", n, mk.MarkerArray(markers=markers))


def is_bag_we_wrote(folder: Path) -> bool:
    """Whether ``folder`` holds exactly what ``write_bag`` writes for a bag folder of its name (a bag of
    an older roarmctl, before the marker file): ``metadata.yaml`` and ``NAME.db3`` or ``NAME.mcap``."""
    try:
        names = {p.name for p in folder.iterdir()}
    except OSError:
        return False
    return names in ({"metadata.yaml", f"{folder.name}.db3"}, {"metadata.yaml", f"{folder.name}.mcap"})


def write_bag(streams: Streams, path: str | os.PathLike, storage: str,
              force: bool = False) -> tuple[Path, dict[str, int]]:
    """Write ``streams`` as a ROS 2 bag. ``storage``: 'mcap' -> the single MCAP file ``path``;
    'sqlite3' -> the bag folder ``path`` (metadata.yaml + .db3). Built in a temporary folder beside the
    target, then renamed into place: an existing MCAP file is replaced, an existing bag folder is
    swapped out and deleted afterwards (``fileio.replace_folder``), and only if roarmctl wrote it
    (``fileio.check_output_folder``) or ``force``. Returns the path and the number of messages per topic."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    target = Path(path)
    if storage == "mcap":
        check_output_file(target)
    else:
        check_output_folder(target, force, made_by_us=is_bag_we_wrote)
        note_output_folder(target)
    tmpdir = new_folder_beside(target)
    try:
        bag = tmpdir / target.stem
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        ts = _typestore()
        with Writer(bag, version=8, storage_plugin=plugin) as writer:
            conns: dict[str, Any] = {}
            counts: dict[str, int] = {}
            for topic, msgtype, ns, msg in messages(streams):
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
                writer.write(conns[topic], ns, ts.serialize_cdr(msg, msgtype))
                counts[topic] = counts.get(topic, 0) + 1
        if storage == "mcap":
            os.replace(bag / f"{bag.name}.mcap", target)
        else:
            replace_folder(bag, target)
    except OSError as exc:
        raise InputError(f"cannot write {target}: {exc.strerror or exc}", "check the disk space and permissions") from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return target, counts

"""How the arm corpus (tests/data/arms/NAME/) was made from the published repositories.

Not run by the tests (it needs the repositories, not the network): kept so that anyone can redo or
extend the corpus and check where every file came from.

    python tests/data/arms/assemble.py --git-root DIR [NAME ...]

``DIR/<owner>+<repo>/repo`` (or ``DIR/<owner>+<repo>``) is a git directory of each repository
(``git clone --bare https://github.com/<owner>/<repo> DIR/<owner>+<repo>``). For every arm the
description files that the URDF and SRDF expansion reads (found by expanding them with xacro and
recording every file opened) and the collision meshes the expanded URDF names are copied, at the
commit below, to ``tests/data/arms/NAME/<path in the repository>``, byte for byte. Collision meshes
larger than ``HULL_ABOVE`` bytes are stored as their convex hull (a binary STL, or COLLADA in metres): roarmctl checks a
mesh's convex hull unless the sidecar asks for ``mesh_collision: exact``, so the collision answers are
the same, and the repository stays small. Visual meshes are left out (roarmctl reads none). Each arm's
``SOURCE`` lists the repository, commit, licence and every file with the git blob id of the published
file (``git rev-parse COMMIT:PATH``); tests/test_arm_corpus.py checks the stored bytes against it.
The sidecar (``robot.yaml``) and the plan (``plan.yaml``) are ours and written by hand.
"""

from __future__ import annotations

import argparse
import builtins
import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
HULL_ABOVE = 100_000  # bytes

#: name -> where it comes from. ``packages``: ROS package name -> its folder in the repository;
#: ``urdf`` / ``srdf`` / ``joint_limits``: paths in the repository; ``xacro_args``: the sidecar's.
ARMS: dict[str, dict] = {
    "xarm6": dict(
        repo="xArm-Developer/xarm_ros2", commit="3654ba7bb2a0e502088251728d07263ea399d4a4",
        licence="BSD-3-Clause", licence_file="LICENSE",
        packages={"xarm_description": "xarm_description", "xarm_moveit_config": "xarm_moveit_config"},
        urdf="xarm_description/urdf/xarm_device.urdf.xacro", srdf="xarm_moveit_config/srdf/xarm.srdf.xacro",
        joint_limits="xarm_moveit_config/config/xarm6/joint_limits.yaml", xacro_args={"dof": 6, "add_gripper": "true", "robot_type": "xarm"}),
    "xarm7": dict(
        repo="xArm-Developer/xarm_ros2", commit="3654ba7bb2a0e502088251728d07263ea399d4a4",
        licence="BSD-3-Clause", licence_file="LICENSE",
        packages={"xarm_description": "xarm_description", "xarm_moveit_config": "xarm_moveit_config"},
        urdf="xarm_description/urdf/xarm_device.urdf.xacro", srdf="xarm_moveit_config/srdf/xarm.srdf.xacro",
        joint_limits="xarm_moveit_config/config/xarm7/joint_limits.yaml", xacro_args={"dof": 7, "add_gripper": "true", "robot_type": "xarm"}),
    "wx250s": dict(
        repo="Interbotix/interbotix_ros_manipulators", commit="a4b7e51150d604e2f16451b703fa5f324dd52520",  # branch humble
        licence="BSD-3-Clause", licence_file="LICENSE",
        packages={"interbotix_xsarm_descriptions": "interbotix_ros_xsarms/interbotix_xsarm_descriptions",
                  "interbotix_xsarm_moveit": "interbotix_ros_xsarms/interbotix_xsarm_moveit"},
        urdf="interbotix_ros_xsarms/interbotix_xsarm_descriptions/urdf/wx250s.urdf.xacro",
        srdf="interbotix_ros_xsarms/interbotix_xsarm_moveit/config/srdf/wx250s.srdf.xacro",
        joint_limits="interbotix_ros_xsarms/interbotix_xsarm_moveit/config/joint_limits/wx250s_joint_limits.yaml"),
    "gen3_lite": dict(
        repo="Kinovarobotics/ros2_kortex", commit="1fdbef345954b326627dc3792981e18e2221450b",
        licence="BSD-3-Clause", licence_file="LICENSE",
        packages={"kortex_description": "kortex_description"},
        urdf="kortex_description/robots/gen3_lite.urdf",
        srdf="kortex_moveit_config/kinova_gen3_lite_moveit_config/config/gen3_lite.srdf",
        joint_limits="kortex_moveit_config/kinova_gen3_lite_moveit_config/config/joint_limits.yaml"),
    "px100": dict(
        repo="Interbotix/interbotix_ros_manipulators", commit="a4b7e51150d604e2f16451b703fa5f324dd52520",  # branch humble
        licence="BSD-3-Clause", licence_file="LICENSE",
        packages={"interbotix_xsarm_descriptions": "interbotix_ros_xsarms/interbotix_xsarm_descriptions",
                  "interbotix_xsarm_moveit": "interbotix_ros_xsarms/interbotix_xsarm_moveit"},
        urdf="interbotix_ros_xsarms/interbotix_xsarm_descriptions/urdf/px100.urdf.xacro",
        srdf="interbotix_ros_xsarms/interbotix_xsarm_moveit/config/srdf/px100.srdf.xacro",
        joint_limits="interbotix_ros_xsarms/interbotix_xsarm_moveit/config/joint_limits/px100_joint_limits.yaml"),
    "fer": dict(
        repo="frankaemika/franka_description", commit="b299b39d9692bfae795184df32a98ce7778d56af",
        licence="Apache-2.0", licence_file="LICENSE", extra=["NOTICE"],
        packages={"franka_description": "."},
        urdf="robots/fer/fer.urdf.xacro", xacro_args={"hand": "true"}),
    "so100": dict(
        repo="TheRobotStudio/SO-ARM100", commit="fda892cba81032c46c40976a48c9ceadbf40a9ca",
        licence="Apache-2.0", licence_file="LICENSE",
        packages={}, urdf="Simulation/SO100/so100.urdf"),
    "open_manipulator_x": dict(
        repo="ROBOTIS-GIT/open_manipulator", commit="3fd6fa94727f863deec52d4f461f39a5fe4d2b10",
        licence="Apache-2.0", licence_file="LICENSE",
        packages={"open_manipulator_description": "open_manipulator_description"},
        urdf="open_manipulator_description/urdf/open_manipulator_x/open_manipulator_x.urdf.xacro",
        srdf="open_manipulator_moveit_config/config/open_manipulator_x/open_manipulator_x.srdf",
        joint_limits="open_manipulator_moveit_config/config/open_manipulator_x/joint_limits.yaml"),
    "ur5e": dict(
        repo="UniversalRobots/Universal_Robots_ROS2_Description", commit="2221ec0f720fb1af99339eb891639b499b62f1da",
        licence="BSD-3-Clause", licence_file="LICENSE",
        packages={"ur_description": "."}, urdf="urdf/ur.urdf.xacro", xacro_args={"ur_type": "ur5e", "name": "ur"}),
    "irb2400": dict(
        repo="ros-industrial/abb", commit="77db19bdb098f50d9569d1cab03ee657627e934e",
        licence="Apache-2.0 (abb_irb2400_support/package.xml)", licence_file=None,
        extra=["abb_irb2400_support/package.xml"],
        packages={"abb_irb2400_support": "abb_irb2400_support"},
        urdf="abb_irb2400_support/urdf/irb2400.urdf",
        srdf="abb_irb2400_moveit_config/config/abb_irb2400.srdf",
        joint_limits="abb_irb2400_moveit_config/config/joint_limits.yaml"),
    "gen3": dict(
        repo="Kinovarobotics/ros2_kortex", commit="1fdbef345954b326627dc3792981e18e2221450b",
        licence="BSD-3-Clause", licence_file="LICENSE",
        packages={"kortex_description": "kortex_description"},
        urdf="kortex_description/robots/gen3.xacro", xacro_args={"dof": 7}),
    "fr3": dict(
        repo="frankaemika/franka_description", commit="b299b39d9692bfae795184df32a98ce7778d56af",
        licence="Apache-2.0", licence_file="LICENSE", extra=["NOTICE"],
        packages={"franka_description": "."},
        urdf="robots/fr3/fr3.urdf.xacro", xacro_args={"hand": "true"}),
    "ar4": dict(
        repo="ycheng517/ar4_ros_driver", commit="ff1c63f4e49519d58db3a773341fb8a101f05804",
        licence="MIT", licence_file="LICENSE",
        packages={"annin_ar4_description": "annin_ar4_description", "annin_ar4_moveit_config": "annin_ar4_moveit_config"},
        urdf="annin_ar4_description/urdf/ar.urdf.xacro", srdf="annin_ar4_moveit_config/srdf/ar.srdf.xacro",
        joint_limits="annin_ar4_moveit_config/config/joint_limits.yaml",  # a ROS 2 parameter file, $(var tf_prefix) keys
        xacro_args={"ar_model": "mk3", "name": "ar", "tf_prefix": ""}),
    "gp7": dict(
        repo="ros-industrial/motoman", commit="433be15f6a27cb9a5715cc3887b1cd15ff33a8cb",
        licence="BSD-3-Clause (motoman_gp7_support/package.xml)", licence_file=None,
        extra=["motoman_gp7_support/package.xml"],
        packages={"motoman_gp7_support": "motoman_gp7_support", "motoman_resources": "motoman_resources"},
        urdf="motoman_gp7_support/urdf/gp7.xacro"),
    "rx160": dict(
        repo="ros-industrial/staubli", commit="367d92ec7432867d9ba87c3399d49a940c4afc67",
        licence="Apache-2.0", licence_file="LICENSE",
        packages={"staubli_rx160_support": "staubli_rx160_support", "staubli_resources": "staubli_resources"},
        urdf="staubli_rx160_support/urdf/rx160.xacro"),
}

TEXT = re.compile(r"\.(xacro|urdf|srdf|yaml|yml|xml|json)$", re.I)


class Repo:
    """A git directory at one commit: file bytes and blob ids."""

    def __init__(self, git_dir: Path, commit: str) -> None:
        self.git_dir, self.commit = git_dir, commit

    def _git(self, *args: str) -> bytes:
        return subprocess.run(["git", "--git-dir", str(self.git_dir), *args], check=True, capture_output=True).stdout

    def files(self, folder: str) -> list[str]:
        out = self._git("ls-tree", "-r", "--name-only", self.commit, *(() if folder in (".", "") else ("--", folder)))
        return out.decode().split()

    def read(self, path: str) -> bytes:
        return self._git("show", f"{self.commit}:{path}")

    def blob(self, path: str) -> str:
        return self._git("rev-parse", f"{self.commit}:{path}").decode().strip()


def _expand_tracking(path: Path, args: dict, packages: dict[str, Path]) -> tuple[str, set[Path]]:
    """xacro-expand ``path``, returning the text and every file opened (an unknown $(find) is a placeholder)."""
    import xacro
    from xacro import substitution_args

    opened: set[Path] = set()
    real_open, real_find = builtins.open, substitution_args._eval_find

    def tracking_open(f, *a, **k):
        opened.add(Path(str(f)).resolve())
        return real_open(f, *a, **k)

    substitution_args._eval_find = lambda pkg: str(packages.get(pkg, Path("/nonexistent") / pkg))
    builtins.open = tracking_open
    try:
        doc = xacro.process_file(str(path), mappings={k: str(v) for k, v in args.items()})
    finally:
        builtins.open, substitution_args._eval_find = real_open, real_find
    return doc.toxml(), opened


def _hull_stl(data: bytes, kind: str = "stl") -> bytes:
    """The convex hull of a mesh file's vertices (scipy's qhull through trimesh), in the same format: a binary
    STL, or a COLLADA file in metres (a declared ``<unit>``, read by pycollada, is applied to the vertices)."""
    import trimesh

    mesh = trimesh.load_mesh(io.BytesIO(data), file_type=kind, process=False)
    if isinstance(mesh, trimesh.Scene):
        mesh = mesh.to_mesh()
    if kind == "dae":
        import collada

        unit = collada.Collada(io.BytesIO(data)).assetInfo.unitmeter or 1.0
        mesh = trimesh.Trimesh(mesh.vertices * unit, mesh.faces, process=False)
    return mesh.convex_hull.export(file_type=kind)


def assemble(name: str, git_root: Path) -> None:
    spec = ARMS[name]
    owner_repo = spec["repo"].replace("/", "+")
    git_dir = next(p for p in (git_root / owner_repo / "repo", git_root / owner_repo) if p.exists())
    repo = Repo(git_dir, spec["commit"])
    dest = HERE / name
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        folders = set(spec["packages"].values()) | {str(Path(spec[k]).parent) for k in ("urdf", "srdf", "joint_limits") if spec.get(k)}
        for folder in folders:  # every description text file of the packages, to expand from
            for f in repo.files(folder):
                if TEXT.search(f):
                    (work / f).parent.mkdir(parents=True, exist_ok=True)
                    (work / f).write_bytes(repo.read(f))
        packages = {pkg: (work / folder).resolve() for pkg, folder in spec["packages"].items()}
        used: set[str] = set()
        texts = []
        for key in ("urdf", "srdf"):
            if not spec.get(key):
                continue
            text, opened = _expand_tracking(work / spec[key], spec.get("xacro_args", {}), packages)
            texts.append(text)
            used |= {str(p.relative_to(work.resolve())) for p in opened if work.resolve() in p.parents}
        if spec.get("joint_limits"):
            used.add(spec["joint_limits"])
        meshes = set()
        urdf_dir = str(Path(spec["urdf"]).parent)
        for m in re.finditer(r"<collision.*?</collision>", texts[0], re.S):
            for fn in re.findall(r'filename="([^"]+)"', m.group(0)):
                if fn.startswith("package://"):
                    pkg, _, rest = fn[len("package://"):].partition("/")
                    meshes.add(os.path.normpath(f"{spec['packages'][pkg]}/{rest}"))
                elif fn.startswith("file://"):
                    meshes.add(str(Path(fn[len("file://"):]).resolve().relative_to(work.resolve())))
                else:
                    meshes.add(os.path.normpath(f"{urdf_dir}/{fn}"))
    if dest.exists():
        for p in dest.iterdir():  # the published files only; SOURCE, robot.yaml and plan.yaml are ours
            if p.is_dir():
                shutil.rmtree(p)
    lines = [f"# {name}: published files of {spec['repo']} (see tests/data/arms/assemble.py)",
             f"repository: https://github.com/{spec['repo']}", f"commit: {spec['commit']}",
             f"licence: {spec['licence']}", "files:  # path here = path in the repository: git blob id of the published file"]
    for f in sorted(used | set(spec.get("extra", [])) | ({spec["licence_file"]} if spec.get("licence_file") else set())):
        (dest / f).parent.mkdir(parents=True, exist_ok=True)
        (dest / f).write_bytes(repo.read(f))
        lines.append(f"  {f}: {repo.blob(f)}")
    lines.append("meshes:  # collision meshes; 'hull of' = stored as the convex hull of the published file")
    for f in sorted(meshes):
        data = repo.read(f)
        (dest / f).parent.mkdir(parents=True, exist_ok=True)
        if len(data) > HULL_ABOVE:  # (a small file, an empty one among them, is kept as published)
            (dest / f).write_bytes(_hull_stl(data, Path(f).suffix.lower().lstrip(".")))
            lines.append(f"  {f}: hull of {repo.blob(f)}")
        else:
            (dest / f).write_bytes(data)
            lines.append(f"  {f}: {repo.blob(f)}")
    (dest / "SOURCE").write_text("\n".join(lines) + "\n")
    size = sum(p.stat().st_size for p in dest.rglob("*") if p.is_file())
    print(f"{name}: {len(used)} description files, {len(meshes)} meshes, {size / 1e3:.0f} kB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--git-root", type=Path, required=True)
    ap.add_argument("names", nargs="*", default=list(ARMS))
    args = ap.parse_args()
    for name in args.names:
        assemble(name, args.git_root)


if __name__ == "__main__":
    sys.exit(main())

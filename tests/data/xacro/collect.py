"""How the xacro corpus (tests/data/xacro/) was made from the published repositories.

Not run by the tests (it needs the repositories, not the network): kept so that anyone can redo or
extend the corpus and check where every file came from.

    python tests/data/xacro/collect.py --git-root DIR

``DIR/<owner>+<repo>/repo`` (or ``DIR/<owner>+<repo>``) is a git directory of each repository
(``git clone --bare https://github.com/<owner>/<repo> DIR/<owner>+<repo>``). Every case below is
expanded with real xacro, recording every file it opens; those files (xacro and the YAML they load,
no meshes) and the repository's licence file are copied, byte for byte, to
``tests/data/xacro/<owner>+<repo>/<path in the repository>``. ``SOURCES.yaml`` lists, per repository,
the commit, the licence, the ROS packages (name -> folder, from each ``package.xml``) and every file
with the git blob id of the published file (``git rev-parse COMMIT:PATH``), and then the cases.
tests/test_xacro_differential.py checks the stored bytes against it and expands every case.
"""

from __future__ import annotations

import argparse
import builtins
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent

#: owner/repo -> (commit, licence as the repository or its package.xml states it, licence file or None)
REPOS: dict[str, tuple[str, str, str | None]] = {
    "ros-industrial/fanuc": ("8fee5e30e535378758ace26dfdffb8ab0403e23c", "BSD-3-Clause", "LICENSE"),
    "ros-industrial/kuka_experimental": ("e78bbd15edb2b39c9053ff3b963ef2947e10a531", "Apache-2.0", "LICENSE"),
    "ros-industrial/motoman": ("433be15f6a27cb9a5715cc3887b1cd15ff33a8cb", "BSD-3-Clause (package.xml)", None),
    "ros-industrial/abb": ("77db19bdb098f50d9569d1cab03ee657627e934e", "Apache-2.0 (package.xml)", None),
    "ros-industrial/staubli": ("367d92ec7432867d9ba87c3399d49a940c4afc67", "Apache-2.0", "LICENSE"),
    "UniversalRobots/Universal_Robots_ROS2_Description": ("2221ec0f720fb1af99339eb891639b499b62f1da", "BSD-3-Clause", "LICENSE"),
    "frankaemika/franka_description": ("b299b39d9692bfae795184df32a98ce7778d56af", "Apache-2.0", "LICENSE"),
    "Kinovarobotics/ros2_kortex": ("1fdbef345954b326627dc3792981e18e2221450b", "BSD-3-Clause", "LICENSE"),
    "xArm-Developer/xarm_ros2": ("3654ba7bb2a0e502088251728d07263ea399d4a4", "BSD-3-Clause", "LICENSE"),
    "Interbotix/interbotix_ros_manipulators": ("0bb2b0e6d0e619bff02cf74dbd5af5681dcf80c9", "BSD-3-Clause", "LICENSE"),
    "ROBOTIS-GIT/open_manipulator": ("3fd6fa94727f863deec52d4f461f39a5fe4d2b10", "Apache-2.0", "LICENSE"),
    "doosan-robotics/doosan-robot2": ("f8c6dc6bce8fe31d6336d5ab630b479c7f2e6d00", "BSD-3-Clause (package.xml)", None),
    "DENSORobot/denso_robot_ros2": ("071363c632eeada53aa0cebab2ed8cf0a0f93ff2", "Apache-2.0", "LICENSE"),
    "ycheng517/ar4_ros_driver": ("ff1c63f4e49519d58db3a773341fb8a101f05804", "MIT", "LICENSE"),
}

#: name -> (owner/repo, top file, xacro arguments)
CASES: dict[str, tuple[str, str, dict[str, str]]] = {
    **{f"fanuc_{n}": ("ros-industrial/fanuc", f"fanuc_{p}_support/urdf/{n}.xacro", {}) for p, n in [
        ("cr7ia", "cr7ia"), ("cr35ia", "cr35ia"), ("lrmate200ic", "lrmate200ic"), ("lrmate200id", "lrmate200id"),
        ("m10ia", "m10ia"), ("m20ia", "m20ia"), ("m430ia", "m430ia2f"), ("m900ib", "m900ib700"),
        ("r1000ia", "r1000ia80f")]},
    **{f"kuka_{n}": ("ros-industrial/kuka_experimental", f"kuka_{p}_support/urdf/{n}.xacro", {}) for p, n in [
        ("kr3", "kr3r540"), ("kr6", "kr6r900sixx"), ("kr10", "kr10r1100sixx"), ("kr16", "kr16_2"),
        ("kr210", "kr210l150"), ("lbr_iiwa", "lbr_iiwa_14_r820")]},
    **{f"motoman_{n}": ("ros-industrial/motoman", f"motoman_{p}_support/urdf/{n}.xacro", {}) for p, n in [
        ("gp7", "gp7"), ("gp12", "gp12"), ("hc10", "hc10"), ("mh5", "mh5"), ("sia20d", "sia20d"),
        ("motomini", "motomini"), ("sda10f", "sda10f")]},
    **{f"abb_{n}": ("ros-industrial/abb", f"abb_{p}_support/urdf/{n}.xacro", {}) for p, n in [
        ("irb2400", "irb2400"), ("irb4400", "irb4400l_30_243"), ("irb5400", "irb5400"),
        ("irb6640", "irb6640_185_280")]},
    "staubli_rx160": ("ros-industrial/staubli", "staubli_rx160_support/urdf/rx160.xacro", {}),
    **{f"ur_{t}": ("UniversalRobots/Universal_Robots_ROS2_Description", "urdf/ur.urdf.xacro", {"ur_type": t, "name": "ur"})
       for t in ("ur3", "ur5e", "ur10e", "ur16e", "ur20", "ur30")},
    "franka_fer_hand": ("frankaemika/franka_description", "robots/fer/fer.urdf.xacro", {"hand": "true"}),
    "franka_fr3": ("frankaemika/franka_description", "robots/fr3/fr3.urdf.xacro", {}),
    "franka_fp3": ("frankaemika/franka_description", "robots/fp3/fp3.urdf.xacro", {}),
    "kinova_gen3": ("Kinovarobotics/ros2_kortex", "kortex_description/robots/gen3.xacro", {"dof": "7"}),
    "kinova_gen3_6dof": ("Kinovarobotics/ros2_kortex", "kortex_description/robots/gen3.xacro", {"dof": "6"}),
    **{f"xarm{d}": ("xArm-Developer/xarm_ros2", "xarm_description/urdf/xarm_device.urdf.xacro",
                    {"dof": str(d), "add_gripper": "true", "robot_type": "xarm"}) for d in (5, 6, 7)},
    "ufactory_lite6": ("xArm-Developer/xarm_ros2", "xarm_description/urdf/xarm_device.urdf.xacro",
                       {"dof": "6", "robot_type": "lite"}),
    "xarm6_srdf": ("xArm-Developer/xarm_ros2", "xarm_moveit_config/srdf/xarm.srdf.xacro",
                   {"dof": "6", "add_gripper": "true", "robot_type": "xarm"}),
    **{f"interbotix_{n}": ("Interbotix/interbotix_ros_manipulators",
                           f"interbotix_ros_xsarms/interbotix_xsarm_descriptions/urdf/{n}.urdf.xacro", {})
       for n in ("px100", "rx150", "wx250s", "vx300s")},
    "interbotix_wx250s_srdf": ("Interbotix/interbotix_ros_manipulators",
                               "interbotix_ros_xsarms/interbotix_xsarm_moveit/config/srdf/wx250s.srdf.xacro", {}),
    "robotis_open_manipulator_x": ("ROBOTIS-GIT/open_manipulator",
                                   "open_manipulator_description/urdf/open_manipulator_x/open_manipulator_x.urdf.xacro", {}),
    "robotis_omy_3m": ("ROBOTIS-GIT/open_manipulator", "open_manipulator_description/urdf/omy_3m/omy_3m.urdf.xacro", {}),
    **{f"doosan_{n}": ("doosan-robotics/doosan-robot2", f"dsr_description2/xacro/{n}.urdf.xacro", {})
       for n in ("m1013", "a0509", "h2515")},
    **{f"denso_{m}": ("DENSORobot/denso_robot_ros2", "denso_robot_descriptions/urdf/denso_robot.urdf.xacro", {"model": m})
       for m in ("cobotta", "vs060")},
    "annin_ar4": ("ycheng517/ar4_ros_driver", "annin_ar4_description/urdf/ar.urdf.xacro", {"ar_model": "mk3"}),
    "annin_ar4_srdf": ("ycheng517/ar4_ros_driver", "annin_ar4_moveit_config/srdf/ar.srdf.xacro", {"name": "ar"}),
}


class Repo:
    """A git directory at one commit: file list, bytes and blob ids."""

    def __init__(self, git_dir: Path, commit: str) -> None:
        self.git_dir, self.commit = git_dir, commit

    def _git(self, *args: str) -> bytes:
        return subprocess.run(["git", "--git-dir", str(self.git_dir), *args], check=True, capture_output=True).stdout

    def files(self) -> list[str]:
        return self._git("ls-tree", "-r", "--name-only", self.commit).decode().split("\n")[:-1]

    def read(self, path: str) -> bytes:
        return self._git("show", f"{self.commit}:{path}")

    def blob(self, path: str) -> str:
        return self._git("rev-parse", f"{self.commit}:{path}").decode().strip()


def packages_of(repo: Repo) -> dict[str, str]:
    """ROS package name -> its folder in the repository, from every package.xml."""
    found = {}
    for f in repo.files():
        if f.endswith("package.xml"):
            m = re.search(rb"<name>\s*([^<\s]+)\s*</name>", repo.read(f))
            if m:
                found[m.group(1).decode()] = str(Path(f).parent) if "/" in f else "."
    return found


def expand_tracking(path: Path, args: dict, packages: dict[str, Path]) -> set[Path]:
    """Every file real xacro opens expanding ``path``."""
    import xacro
    from xacro import substitution_args

    opened: set[Path] = set()
    real_open, real_find = builtins.open, substitution_args._eval_find

    def tracking_open(f, *a, **k):
        opened.add(Path(str(f)).resolve())
        return real_open(f, *a, **k)

    substitution_args._eval_find = lambda pkg: str(packages[pkg])
    builtins.open = tracking_open
    try:
        xacro.process_file(str(path), mappings=dict(args))
    finally:
        builtins.open, substitution_args._eval_find = real_open, real_find
    return opened


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--git-root", type=Path, required=True)
    opts = ap.parse_args()
    sources: dict = {"repositories": {}, "cases": {}}
    used: dict[str, set[str]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for full, (commit, licence, licence_file) in REPOS.items():
            slug = full.replace("/", "+")
            git_dir = next(p for p in (opts.git_root / slug / "repo", opts.git_root / slug) if p.exists())
            repo = Repo(git_dir, commit)
            work = Path(tmp) / slug
            for f in repo.files():  # every text file a description may read, to expand from
                if re.search(r"\.(xacro|urdf|yaml|yml|xml)$", f):
                    (work / f).parent.mkdir(parents=True, exist_ok=True)
                    (work / f).write_bytes(repo.read(f))
            pkgs = packages_of(repo)
            files = used.setdefault(full, {licence_file} if licence_file else set())
            for name, (case_repo, top, args) in CASES.items():
                if case_repo != full:
                    continue
                try:
                    opened = expand_tracking(work / top, args, {p: (work / d).resolve() for p, d in pkgs.items()})
                except Exception as exc:  # noqa: BLE001 - a case real xacro cannot expand is left out
                    print(f"{name}: left out: real xacro fails: {str(exc)[:200]}", file=sys.stderr)
                    continue
                files |= {str(p.relative_to(work.resolve())) for p in opened if work.resolve() in p.parents}
                sources["cases"][name] = {"repository": full, "file": top, "args": args}
            texts = [repo.read(f) for f in files]  # the packages a stored file names ($(find), package://)
            sources["repositories"][full] = {
                "commit": commit, "licence": licence,
                "packages": {p: d for p, d in sorted(pkgs.items()) if any(p.encode() in b for b in texts)},
                "files": {f: repo.blob(f) for f in sorted(files)}}
            dest = HERE / slug
            for f in files:
                (dest / f).parent.mkdir(parents=True, exist_ok=True)
                (dest / f).write_bytes(repo.read(f))
            print(f"{full}: {len(files)} files", file=sys.stderr)
    header = "# Published xacro descriptions, byte for byte (see tests/data/xacro/collect.py)\n"
    (HERE / "SOURCES.yaml").write_text(header + yaml.safe_dump(sources, sort_keys=False, width=200))


if __name__ == "__main__":
    main()

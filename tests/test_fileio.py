"""Atomic writes: all or nothing, and the usual file mode."""

import os

import pytest

from roarmctl.fileio import atomic_write_text, atomic_write_with


def test_write_replaces_whole_file_with_umask_mode(tmp_path):
    target = tmp_path / "out.json"
    atomic_write_text(target, "first")
    atomic_write_text(target, "second")
    assert target.read_text() == "second"
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask


def test_interrupted_write_leaves_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "traj.json"
    atomic_write_text(target, "old")

    def writer(f):
        f.write(b"half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write_with(target, writer)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["traj.json"]


def test_unwritable_target_is_an_input_error(tmp_path):
    from roarmctl.errors import InputError

    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(InputError, match="cannot write"):
        atomic_write_text(blocker / "sub" / "out.json", "data")  # a file where a directory should be


def test_a_device_or_directory_is_never_replaced(tmp_path):
    """A rename over /dev/null or a serial port (as root, in a writable /dev) would replace the device
    node with a regular file; a FIFO stands in for a device here."""
    from roarmctl.errors import InputError

    fifo = tmp_path / "device"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        atomic_write_text(fifo, "data")
    assert not fifo.is_file() and fifo.exists()
    with pytest.raises(InputError, match="a folder"):
        atomic_write_text(tmp_path, "data")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["device"]

import os
import subprocess

import numpy as np
import pytest

from stmpl.files import atomic_path, atomic_savez, atomic_write_text, folder_lock


def test_atomic_writes_replace_whole_files_with_ordinary_permissions(tmp_path):
    umask = os.umask(0o022)
    try:
        f = atomic_write_text(tmp_path / "a.json", "{}")
        assert f.read_text() == "{}" and (f.stat().st_mode & 0o777) == 0o644
        z = atomic_savez(tmp_path / "a.npz", {"x": np.arange(3)})
        assert (z.stat().st_mode & 0o777) == 0o644
        np.testing.assert_array_equal(np.load(z)["x"], np.arange(3))
    finally:
        os.umask(umask)
    with pytest.raises(RuntimeError):
        with atomic_path(tmp_path / "a.json") as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert (tmp_path / "a.json").read_text() == "{}"  # the old file stays
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "a.npz"]  # no debris


def test_a_folder_is_held_by_one_living_process_at_a_time(tmp_path):
    lock = tmp_path / ".lock"
    with folder_lock(tmp_path, "a run"):
        assert lock.read_text().split()[0] == str(os.getpid())
    assert not lock.exists()  # let go at the end
    lock.write_text(f"{os.getppid()} another run\n")  # a living process holds it
    with pytest.raises(RuntimeError, match=rf"held by another run \(process {os.getppid()}\)"):
        with folder_lock(tmp_path, "a run"):
            pass
    assert lock.read_text().startswith(str(os.getppid()))  # not taken from it
    gone = subprocess.Popen(["true"])
    gone.wait()
    lock.write_text(f"{gone.pid} a run that was killed\n")
    with folder_lock(tmp_path, "a run"):  # a dead process's lock is taken over
        assert lock.read_text().split()[0] == str(os.getpid())
    assert not lock.exists()

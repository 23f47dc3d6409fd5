"""Files under races, signals and full disks (issue 22, section 3): the atomic writer."""

from __future__ import annotations

import errno
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from napari_swa_imesh import _atomic
from napari_swa_imesh.io import atomic_write, check_writable, write_labels

SRC = str(Path(__file__).resolve().parents[1] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", "")}


def _temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".swa-imesh"))


def _wait_for(condition, what: str, timeout: float = 120.0) -> None:
    # a generous limit only to stop a hung test; nothing here asserts a duration
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            pytest.fail(f"gave up waiting for {what}")
        time.sleep(0.02)


# ------------------------------------------------------------------- two writers, one name

WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from napari_swa_imesh.io import atomic_write
    folder, me = Path(sys.argv[1]), sys.argv[2]
    names = sys.argv[3:]
    try:
        with atomic_write([folder / n for n in names]) as temps:
            for tmp in temps:
                tmp.write_text(me)
            # the barrier: both runs have passed the existence check and written
            (folder / f"ready-{me}").touch()
            while len(list(folder.glob("ready-*"))) < 2:
                time.sleep(0.005)
    except FileExistsError as exc:
        print(exc, file=sys.stderr)
        sys.exit(2)
""")


@pytest.mark.parametrize("names", [["m.vtu"], ["m.xdmf", "m.h5", "m_xdmf_facets.vtu"]])
def test_two_runs_on_one_output_exactly_one_wins(tmp_path, names):
    for attempt in range(6):
        folder = tmp_path / str(attempt)
        folder.mkdir()
        # the second run lists its targets in the other order, so multi-file runs can
        # each win a name before losing one (the all-or-nothing take-back)
        runs = [subprocess.Popen([sys.executable, "-c", WRITER, str(folder), me,
                                  *(names if me == "a" else names[::-1])],
                                 env=ENV, stderr=subprocess.PIPE, text=True)
                for me in ("a", "b")]
        codes, errs = zip(*((r.wait(timeout=120), r.stderr.read()) for r in runs))
        assert sorted(codes) == [0, 2], errs
        winner = "ab"[codes.index(0)]
        assert "appeared while this run was working" in errs[codes.index(2)]
        assert {n: (folder / n).read_text() for n in names} == {n: winner for n in names}
        assert _temporaries(folder) == []


def test_two_mesh_commands_on_one_output_never_both_succeed(tmp_path):
    # no barrier: whichever way they interleave (refused at the door or when placing),
    # exactly one run writes and the other says why in one sentence
    np.save(tmp_path / "l.npy", np.arange(4 * 5 * 6).reshape(4, 5, 6) % 3)
    for attempt in range(3):
        out = tmp_path / f"m{attempt}.vtu"
        runs = [subprocess.Popen([sys.executable, "-m", "napari_swa_imesh.cli", "mesh",
                                  str(tmp_path / "l.npy"), "-o", str(out)], env=ENV,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                for _ in range(2)]
        codes = [r.wait(timeout=300) for r in runs]
        errs = [r.stderr.read() for r in runs]
        assert sorted(codes) == [0, 2], errs
        loser = errs[codes.index(2)]
        assert loser.count("\n") == 1 and ("already exists" in loser or "appeared" in loser)
        assert sum("wrote " in r.stdout.read() for r in runs) == 1
    assert _temporaries(tmp_path) == []


def test_a_target_appearing_mid_run_takes_back_what_this_run_published(tmp_path):
    a, b, store = tmp_path / "a.txt", tmp_path / "b.txt", tmp_path / "s.zarr"
    with pytest.raises(FileExistsError, match="b.txt appeared while this run"):
        with atomic_write([a, store, b]) as (ta, ts, tb):
            ta.write_text("mine")
            ts.mkdir()
            (ts / "chunk").write_text("mine")
            tb.write_text("mine")
            b.write_text("theirs")          # another program, between check and publish
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.txt"]
    assert b.read_text() == "theirs"


def test_an_interrupt_while_placing_takes_back_what_was_placed(tmp_path, monkeypatch):
    real, placed = _atomic._claim, []

    def stopped_at_the_second(tmp, target):
        if placed:
            raise KeyboardInterrupt
        real(tmp, target)
        placed.append(target)

    monkeypatch.setattr(_atomic, "_claim", stopped_at_the_second)
    with pytest.raises(KeyboardInterrupt):
        with atomic_write([tmp_path / "a.txt", tmp_path / "b.txt"]) as temps:
            for tmp in temps:
                tmp.write_text("mine")
    assert placed == [tmp_path / "a.txt"] and list(tmp_path.iterdir()) == []


def test_a_store_appearing_mid_run_is_refused_and_kept(tmp_path):
    store = tmp_path / "s.zarr"
    with pytest.raises(FileExistsError, match="appeared"):
        with atomic_write([store]) as (tmp,):
            tmp.mkdir()
            store.mkdir()
            (store / "theirs").write_text("x")
    assert [p.name for p in store.iterdir()] == ["theirs"]
    assert _temporaries(tmp_path) == []


def test_without_hard_links_an_exclusive_create_claims_the_name(tmp_path, monkeypatch):
    def no_links(src, dst):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(_atomic.os, "link", no_links)
    with atomic_write([tmp_path / "a.txt"]) as (tmp,):
        tmp.write_text("first")
    assert (tmp_path / "a.txt").read_text() == "first"
    with pytest.raises(FileExistsError, match="appeared"):
        with atomic_write([tmp_path / "b.txt"]) as (tmp,):
            tmp.write_text("mine")
            (tmp_path / "b.txt").write_text("theirs")
    assert (tmp_path / "b.txt").read_text() == "theirs"
    assert _temporaries(tmp_path) == []


def test_a_dangling_symlink_counts_as_existing(tmp_path):
    link = tmp_path / "m.npy"
    link.symlink_to(tmp_path / "nowhere" / "x.npy")
    with pytest.raises(FileExistsError, match="a link to nothing"):
        check_writable(link)
    with pytest.raises(FileExistsError):
        write_labels(link, np.ones((3, 3), np.uint8))
    assert link.is_symlink() and not link.exists()
    write_labels(link, np.ones((3, 3), np.uint8), force=True)
    assert not link.is_symlink() and np.load(link).sum() == 9
    assert not (tmp_path / "nowhere").exists()


def test_the_cli_refuses_a_dangling_symlink_output(tmp_path, capsys):
    from napari_swa_imesh.cli import main

    np.save(tmp_path / "l.npy", np.ones((4, 4, 4), np.uint8))
    (tmp_path / "m.vtu").symlink_to(tmp_path / "gone.vtu")
    assert main(["mesh", str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.vtu")]) == 2
    assert "a link to nothing" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.npy", "m.vtu"]


# ------------------------------------------------------------------------------ signals

STOPPED_WRITER = textwrap.dedent("""
    import sys, time
    import napari_swa_imesh.mesh.formats._export as export
    from napari_swa_imesh.cli import main

    def slow_write(ex, temps, **options):
        # a big partial file, then wait for the signal (as a long write would)
        with open(temps[0], "wb") as fh:
            fh.write(b"x" * (8 << 20))
            fh.flush()
            time.sleep(600)

    export._write = slow_write
    sys.exit(main(sys.argv[1:]))
""")


def test_sigterm_during_a_write_leaves_nothing(tmp_path):
    np.save(tmp_path / "l.npy", np.ones((4, 4, 4), np.uint8))
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    run = subprocess.Popen([sys.executable, "-c", STOPPED_WRITER, "mesh",
                            str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.vtu")],
                           env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def partial_written():
        return any(f.stat().st_size == 8 << 20 for t in tmp_path.glob(".swa-imesh-*")
                   for f in t.iterdir())

    try:
        _wait_for(partial_written, "the partial file")
        run.send_signal(signal.SIGTERM)
        code = run.wait(timeout=120)
    finally:
        run.kill()
    err = run.stderr.read()
    assert code == 128 + signal.SIGTERM, err
    assert err.strip().count("\n") == 0 and "stopped by SIGTERM" in err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_sigterm_during_a_real_mesh_write_leaves_nothing_or_everything(tmp_path):
    labels = np.zeros((100, 100, 100), np.uint8)
    labels[:, :, 51:] = 1
    labels[20:77, 20:81, 10:95] = 2
    np.save(tmp_path / "l.npy", labels)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    run = subprocess.Popen([sys.executable, "-m", "napari_swa_imesh.cli", "mesh",
                            str(tmp_path / "l.npy"), "-o", str(tmp_path / "m.vtu")],
                           env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: bool(_temporaries(tmp_path)) or run.poll() is not None,
                  "the temporary folder")
        run.send_signal(signal.SIGTERM)
        code = run.wait(timeout=120)
    finally:
        run.kill()
    err = run.stderr.read()
    assert _temporaries(tmp_path) == []
    if code == 0:           # the signal came after the files were placed: all of them
        assert sorted(p.name for p in tmp_path.iterdir()) == ["l.npy", "m.vtu",
                                                              "m_facets.vtu"]
    else:
        assert code == 128 + signal.SIGTERM and "stopped by SIGTERM" in err, err
        assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


# ------------------------------------------------------------------- stale temporaries

def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_later_run_removes_temporaries_of_dead_owners_only(tmp_path):
    host = _atomic._host()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        names = {
            "dead": f".swa-imesh-{_dead_pid()}@{host}-abcd1234",
            "live": f".swa-imesh-{live.pid}@{host}-abcd1234",
            "mine": f".swa-imesh-{os.getpid()}@{host}-abcd1234",
            "other host": f".swa-imesh-{_dead_pid()}@not{host}-abcd1234",
            "old style": ".swa-imesh-abcd1234",
        }
        for name in names.values():
            (tmp_path / name).mkdir()
            (tmp_path / name / "partial.vtu").write_bytes(b"x" * 100)
        with atomic_write([tmp_path / "a.txt"]) as (tmp,):
            tmp.write_text("new")
        assert _temporaries(tmp_path) == sorted(v for k, v in names.items() if k != "dead")
    finally:
        live.kill()
        live.wait()


def test_temporary_folders_carry_their_owner(tmp_path):
    with atomic_write([tmp_path / "a.txt"]) as (tmp,):
        match = _atomic._TEMP_NAME.fullmatch(tmp.parent.name)
        assert match and int(match.group(1)) == os.getpid()
        assert match.group(2) == _atomic._host()
        tmp.write_text("x")
    assert socket.gethostname()


# --------------------------------------------------------------------------- full disks

@pytest.mark.parametrize("error", [
    OSError(errno.ENOSPC, "No space left on device"),
    OSError(errno.EDQUOT, "Disk quota exceeded"),
    OSError("4096 requested and 3968 written"),           # numpy's tofile
    RuntimeError("Can't decrement id ref count (file write failed: errno = 28, error "
                 "message = 'No space left on device')"),  # h5py
])
def test_a_full_disk_is_one_sentence_and_leaves_nothing(tmp_path, error):
    with pytest.raises(OSError, match=r"^the disk holding .* is full \(it filled after "
                                      r"100 kB of output\); free space") as info:
        with atomic_write([tmp_path / "a.npy", tmp_path / "b.npy"]) as (a, b):
            a.write_bytes(b"x" * (100 << 10))
            raise error
    assert info.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []


def test_other_errors_pass_unchanged(tmp_path):
    with pytest.raises(OSError, match="^permission trouble$"):
        with atomic_write([tmp_path / "a.npy"]):
            raise OSError("permission trouble")


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MB tmpfs (needs root and mount rights; skipped where that is not allowed)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)],
                              capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"cannot mount a small tmpfs to fill: {exc}")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill: {done.stderr.strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], timeout=30)


@pytest.mark.parametrize("command,suffix", [("mesh", ".xdmf"), ("mesh", ".vtu"),
                                            ("mesh", ".msh"), ("simulate", ".xdmf")])
def test_a_real_full_disk_gives_one_sentence_exit_2(tmp_path, small_disk, command, suffix):
    labels = np.zeros((60, 60, 60), np.uint8)
    labels[:, :, 31:] = 1
    labels[10:37, 10:41, 5:45] = 2
    np.save(tmp_path / "l.npy", labels)
    extra = ["-k", "0=1", "1=2", "2=3"] if command == "simulate" else []
    run = subprocess.run([sys.executable, "-m", "napari_swa_imesh.cli", command,
                          str(tmp_path / "l.npy"), *extra,
                          "-o", str(small_disk / f"m{suffix}")],
                         env=ENV, capture_output=True, text=True, timeout=600)
    assert run.returncode == 2, run.stderr[-2000:]
    assert run.stderr.count("\n") == 1 and "is full" in run.stderr
    assert list(small_disk.iterdir()) == []


@pytest.mark.parametrize("suffix", [".npy", ".tif", ".nii.gz", ".nii"])
def test_labels_onto_a_real_full_disk(small_disk, suffix):
    rng = np.random.default_rng(0)
    with pytest.raises(OSError, match="is full"):
        write_labels(small_disk / f"l{suffix}", rng.integers(0, 2**31, (600, 600), np.int64))
    assert list(small_disk.iterdir()) == []

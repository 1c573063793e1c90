"""Server memory over many browser connections: ``python -m bench.perf.soak [--quick]``.

The app is served as a person would serve it (``python launch.py`` in its own process, the
bundled checkpoint, a synthetic root generated for the run: 8 frames, seed 0, camera images
included, the ``train`` split of 6 frames), and a client connects and disconnects ``--cycles``
times, one after the other. Each connection does what a browser's visit does: it registers,
receives the scene and the panel, presses *Next* (the frame, its camera image and its encoding
change), runs a prompt and waits for the answer's heatmap, then leaves. The server's resident
memory (``VmRSS`` of its process) is read every ``--every`` cycles twice: at once (*busy*) and
after a pause of :data:`SETTLE_SECONDS` (*at rest*).

The target: after ``--warm-up`` cycles (the frame, feature and text caches fill, the allocator
settles), RSS at rest stays within ``--bound`` MB of its value then. ``--baseline PATH`` serves the same
workload with another checkout's ``launch.py`` as well (e.g. ``git worktree add /tmp/before
aa2a985``: the code before issue 21), side by side, each cycle visiting both in turn (the same
load for both, so their seconds per visit compare), and puts its RSS beside this checkout's.

The client speaks viser 1.1.1's websocket protocol directly (``websockets``, ``msgpack``,
``zstd``), as the web client does: a benchmark imports neither ``app`` nor the tests.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import msgspec
import viser
import zstandard
from tqdm import tqdm
from websockets.sync.client import connect

from bench.common import REPO, RESULTS_DIR, BenchResult, Table, Target, machine_info, write_result
from scenes.synth.generate import SynthSettings, generate_root
from scenes.utils.cli import command_parser, option

PROMPT = "the car ahead"
SPLIT = "train"
START_TIMEOUT = 300.0
"""Seconds the server may take to listen and warm up."""

SETTLE_SECONDS = 10.0
"""Pause between the two readings: *busy* is RSS right after a visit (the last seconds'
visitors may not be collected yet), *at rest* after this pause, once the server has collected
what the departed browsers left and trimmed its heap (its reaper collects 0.5 s after a
disconnect, at most every 2 s, and trims after 5 s without one; a full collection takes up to
a second on a loaded machine)."""

STEP_TIMEOUT = 120.0
"""Seconds one step of a visit may take (a loaded 2-core machine is slow)."""


def decode_frame(frame: bytes) -> list[dict]:
    """The messages of one server frame: ``[u64 raw][u64 zstd][zstd(msgpack)][binary]``."""
    raw_len = int.from_bytes(frame[:8], "little")
    zstd_len = int.from_bytes(frame[8:16], "little")
    payload = zstandard.ZstdDecompressor().decompress(
        frame[16 : 16 + zstd_len], max_output_size=raw_len
    )
    return msgspec.msgpack.decode(payload)["messages"]


class Visit:
    """One browser visit: connect, receive the panel, act, leave."""

    def __init__(self, port: int) -> None:
        self.ws = connect(
            f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"], max_size=None
        )
        self.labels: dict[str, str] = {}
        self._send(
            {
                "type": "ViewerCameraMessage",
                "wxyz": [1.0, 0.0, 0.0, 0.0],
                "position": [-10.0, 0.0, 5.0],
                "fov": 1.0,
                "near": 0.01,
                "far": 1000.0,
                "image_height": 600,
                "image_width": 800,
                "look_at": [10.0, 0.0, 0.0],
                "up_direction": [0.0, 0.0, 1.0],
            }
        )

    def _send(self, message: dict) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def until(self, kind: str, name: str, label: str | None = None) -> None:
        """Read until a ``kind`` message (e.g. ``PointCloudMessage``) of the scene node ``name``
        arrives and the widget ``label`` is known."""
        deadline = time.monotonic() + STEP_TIMEOUT
        seen = False
        while not (seen and (label is None or label in self.labels)):
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {name!r} within {STEP_TIMEOUT:g} s")
            for m in decode_frame(self.ws.recv(timeout=STEP_TIMEOUT)):
                props = m.get("props")
                if isinstance(props, dict) and props.get("label"):
                    self.labels[props["label"]] = m["uuid"]
                seen = seen or (m["type"] == kind and m.get("name") == name)

    def set(self, label: str, value: object) -> None:
        self._send(
            {"type": "GuiUpdateMessage", "uuid": self.labels[label], "updates": {"value": value}}
        )

    def close(self) -> None:
        self.ws.close()


def visit(port: int) -> None:
    """What one browser does (see the module docstring)."""
    v = Visit(port)
    try:
        v.until("PointCloudMessage", "/scene/lidar", "Prompt")
        v.set("Frame", "Next")
        v.until("PointCloudMessage", "/scene/lidar")  # the next frame's points
        v.set("Prompt", PROMPT + "\n")
        v.until("ImageMessage", "/heatmap")  # the answer
    finally:
        v.close()


def rss_mb(pid: int) -> float:
    """Resident memory of process ``pid`` (MB)."""
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise OSError(f"no VmRSS for process {pid}")


def serve(launch: Path, root: Path, work: Path) -> tuple[subprocess.Popen, int]:
    """Start ``launch.py`` on ``root`` (port 0, one thread); returns the process and its port."""
    log = work / f"server-{len(list(work.glob('server-*.log')))}.log"
    cmd = [sys.executable, str(launch), "--data", str(root), "--split", SPLIT, "--port", "0"]
    cmd += ["--pairs", str(work / "pairs"), "--threads", "1"]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    out = log.open("w")
    proc = subprocess.Popen(
        cmd, stdout=out, stderr=subprocess.STDOUT, cwd=launch.parent, env=env, text=True
    )
    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline:
        found = re.search(r"http://127\.0\.0\.1:(\d+)", log.read_text())
        if found:
            return proc, int(found.group(1))
        if proc.poll() is not None:
            raise RuntimeError(f"{shlex.join(cmd)} exited with {proc.returncode}: see {log}")
        time.sleep(0.5)
    proc.kill()
    raise TimeoutError(f"{shlex.join(cmd)} did not listen within {START_TIMEOUT:g} s")


def soak(launches: dict[str, Path], root: Path, work: Path, cycles: int, every: int) -> dict:
    """RSS of a server of each ``launches`` entry every ``every`` cycles, busy and at rest
    (cycle 0: after one warm visit), and the seconds spent visiting each. The servers run side
    by side and each cycle visits them in turn, so that they see the same load."""
    servers: dict[str, tuple[subprocess.Popen, int]] = {}
    try:
        for name, launch in launches.items():
            servers[name] = serve(launch, root, work)
        for _, port in servers.values():
            visit(port)  # the model is warm and the first frame encoded
        out = {n: {"busy_mb": {}, "rest_mb": {}, "seconds": 0.0} for n in servers}

        def read(cycle: int) -> None:
            for n, (proc, _) in servers.items():
                out[n]["busy_mb"][cycle] = rss_mb(proc.pid)
            time.sleep(SETTLE_SECONDS)
            for n, (proc, _) in servers.items():
                out[n]["rest_mb"][cycle] = rss_mb(proc.pid)

        read(0)
        for cycle in tqdm(range(1, cycles + 1), desc=" and ".join(servers), unit="visit"):
            for n, (_, port) in servers.items():
                start = time.monotonic()
                visit(port)
                out[n]["seconds"] += time.monotonic() - start
            if cycle % every == 0:
                read(cycle)
        return out
    finally:
        for proc, _ in servers.values():
            proc.terminate()
        for proc, _ in servers.values():
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()


def growth(rss: dict[int, float], warm_up: int) -> float:
    """The largest RSS after the warm-up minus RSS at its end (MB)."""
    base = rss[max(c for c in rss if c <= warm_up)]
    return max(v for c, v in rss.items() if c >= warm_up) - base


def _commit(launch: Path) -> str:
    """The git commit of the checkout ``launch`` belongs to (``"unknown"`` outside git), and
    ``+changes`` when its working tree differs from it."""
    where = ["git", "-C", str(launch.parent)]
    try:
        head = subprocess.run(
            [*where, "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        )
        dirty = subprocess.run(
            [*where, "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
        )
    except OSError:
        return "unknown"
    if head.returncode != 0:
        return "unknown"
    return head.stdout.strip() + (" +changes" if dirty.stdout.strip() else "")


def run(args: argparse.Namespace, command: str) -> BenchResult:
    start = time.perf_counter()
    machine = machine_info(command)
    runs = {"this checkout": REPO / "launch.py"}
    if args.baseline is not None:
        runs["baseline"] = args.baseline.resolve()
    with tempfile.TemporaryDirectory(prefix="talk2pc-soak-") as tmp:
        work = Path(tmp)
        root = work / "root"
        generate_root(root, args.frames, SynthSettings(seed=0))
        results = soak(runs, root, work, args.cycles, args.every)
    names = list(results)
    cycles = sorted(results[names[0]]["rest_mb"])
    kinds = ("busy_mb", "rest_mb")
    rows = [(str(c), *(f"{results[n][k][c]:.0f}" for n in names for k in kinds)) for c in cycles]
    grown = {(n, k): growth(results[n][k], args.warm_up) for n in names for k in kinds}
    rows.append(
        (
            f"growth after visit {args.warm_up}",
            *(f"{grown[n, k]:+.0f}" for n in names for k in kinds),
        )
    )
    per_visit = {n: results[n]["seconds"] / args.cycles for n in names}
    table = Table(
        title=f"Server RSS (MB) every {args.every} visits: busy (at once) and at rest "
        f"(after {SETTLE_SECONDS:g} s)",
        columns=("visits", *(f"{n}, {k}" for n in names for k in ("busy", "at rest"))),
        rows=tuple(rows),
        align=("l", *("r" for _ in names for _ in kinds)),
        notes=tuple(f"{n}: {runs[n]} (commit {_commit(runs[n])})" for n in names),
    )
    target = Target(
        name=f"Server RSS growth at rest after {args.warm_up} visits, over {args.cycles}",
        value=grown["this checkout", "rest_mb"],
        limit=args.bound,
        unit="MB",
        higher_is_better=False,
    )
    findings = [
        target.describe(),
        "Growth busy (the last seconds' visitors not collected yet): "
        + ", ".join(f"{n} {grown[n, 'busy_mb']:+.0f} MB" for n in names)
        + "; at rest: "
        + ", ".join(f"{n} {grown[n, 'rest_mb']:+.0f} MB" for n in names)
        + ".",
        f"A visit: connect, panel and scene, *Next*, the prompt {PROMPT!r} and its answer, "
        f"disconnect; {', '.join(f'{n}: {per_visit[n]:.2f} s a visit' for n in names)} "
        "(the servers run side by side, visited in turn: the same load).",
        f"Root: synthetic, {args.frames} frames, seed 0, split {SPLIT!r}; the bundled checkpoint.",
    ]
    data = {
        "targets": [asdict(target)],
        "runs": {n: {"launch": str(runs[n]), **results[n]} for n in names},
        "cycles": args.cycles,
        "warm_up": args.warm_up,
        "every": args.every,
    }
    return BenchResult(
        name="soak",
        title="Memory per connection: a soak of browser visits",
        machine=machine,
        tables=(table,),
        findings=tuple(findings),
        data=data,
        seconds=time.perf_counter() - start,
    )


@dataclass(frozen=True, kw_only=True)
class SoakOptions:
    """The flags of ``python -m bench.perf.soak`` (None: the quick or full run's value)."""

    quick: bool = option(False, help="60 visits, warm-up 20 (a smoke run)")
    cycles: int | None = option(None, help="visits (default 300)")
    warm_up: int | None = option(None, help="visits before the target (50)")
    every: int | None = option(None, help="visits between readings (25)")
    bound: float = option(50.0, help="allowed growth, MB (default %(default)s)")
    frames: int = option(8, help="frames of the synthetic root")
    baseline: Path | None = option(None, help="another checkout's launch.py")
    threads: int = option(1, help="ignored (the server uses 1)")
    out_dir: Path = option(RESULTS_DIR, help="where the JSON goes")


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.perf.soak``'s parser."""
    return command_parser("python -m bench.perf.soak", __doc__.splitlines()[0], SoakOptions)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = build_parser()
    args = p.parse_args(argv)
    quick = {"cycles": 60, "warm_up": 20, "every": 10}
    full = {"cycles": 300, "warm_up": 50, "every": 25}
    for key, value in (quick if args.quick else full).items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    if not 0 < args.warm_up < args.cycles or args.every < 1:
        p.error("need 0 < --warm-up < --cycles and --every >= 1")
    result = run(args, shlex.join(["python", "-m", "bench.perf.soak", *argv]))
    print(result.to_markdown())
    print(f"wrote {write_result(result, args.out_dir)}")
    return 0 if result.data["targets"][0]["value"] <= args.bound else 1


if __name__ == "__main__":
    raise SystemExit(main())

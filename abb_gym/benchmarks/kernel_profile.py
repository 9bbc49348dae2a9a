"""Where the vector environment's step spends its time, by compiled function, with Linux
``perf``.

    python -m abb_gym.benchmarks.kernel_profile [--envs 1024] [--precision float64]
                                                [--seconds 8] [--top 15]
                                                [--scene yoshida_odd] [--integrator rk4]

numba's compiled code is anonymous memory to ``perf``: its samples show as bare addresses
("[JIT] tid ...").  ``perf`` names such code from a map file, ``/tmp/perf-<pid>.map``
(lines ``start size name``, hexadecimal).  :func:`write_perf_map` writes one for every
function that numba compiled *in this process* (a kernel loaded from the on-disk cache keeps no
names, so the profiled process compiles with an empty cache of its own: a minute or two).

The command starts such a process, which builds the vector environment (``yoshida_odd``
unless ``--scene`` names another, with the scene's balls where it puts them for any other;
10 ms steps, 100-step episodes: the rows of ``abb-gym bench speed``), steps it until every
kernel is compiled, writes the map and says so; only then does ``perf record`` attach to it
(``-p``), so the profile holds the steady state only, compile excluded.  It prints the
share of all samples (both threads) by library and by function.  Compiled functions that the
compiler inlined into their callers count as their callers.

Needs ``perf`` on the PATH and permission to attach (``kernel.perf_event_paranoid`` <= 2
for a child process of one's own).  docs/performance.md says where the vector step's time
goes, and how to read a profile.
"""
from __future__ import annotations

import argparse
import gc
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from ..physics.methods import COMPILED_METHODS, PRECISIONS

__all__ = ["write_perf_map", "readable_name", "profile", "main"]

READY = "kernel_profile: ready"


def _compiled_symbols() -> dict[int, str]:
    """Start address -> symbol of every function numba compiled in this process."""
    from numba.core.dispatcher import Dispatcher
    symbols: dict[int, str] = {}
    for obj in gc.get_objects():
        # type(), not isinstance(): isinstance asks a weak proxy for its class, and a dead
        # proxy (the garbage collector lists them) raises ReferenceError
        if not issubclass(type(obj), Dispatcher):
            continue
        for cres in list(obj.overloads.values()):
            library = getattr(cres, "library", None)
            module = getattr(library, "_final_module", None)
            if module is None:
                continue  # loaded from the cache: no names kept
            for fn in module.functions:
                if fn.is_declaration:
                    continue
                try:
                    address = library.get_pointer_to_function(fn.name)
                except Exception:  # noqa: BLE001 (a symbol the engine did not emit)
                    continue
                if address:
                    symbols[address] = fn.name
    return symbols


def write_perf_map(path: str | os.PathLike | None = None) -> tuple[Path, int]:
    """Write the ``perf`` map of every function compiled in this process to ``path``
    (default ``/tmp/perf-<pid>.map``, where ``perf report`` looks).  A function's size is
    the distance to the next one (at most 4 MiB).  Returns the path and the count."""
    path = Path(path or f"/tmp/perf-{os.getpid()}.map")
    symbols = _compiled_symbols()
    starts = sorted(symbols)
    with open(path, "w", encoding="ascii", errors="replace") as fh:
        for k, start in enumerate(starts):
            gap = starts[k + 1] - start if k + 1 < len(starts) else 4096
            size = gap if 0 < gap <= 1 << 22 else 4096
            fh.write(f"{start:x} {size:x} {symbols[start]}\n")
    return path, len(starts)


_NESTED_NAME = re.compile(r"_ZN((?:\d+[A-Za-z_][A-Za-z0-9_]*)+?)(?:B\d|E)")


def readable_name(symbol: str) -> str:
    """``abb_gym.physics.model.accelerations_block`` from numba's mangled symbol
    (``_ZN7abb_gym7physics5model19accelerations_blockB4v130B64...``); other names as given."""
    match = _NESTED_NAME.match(symbol)
    if not match:
        return symbol
    parts, text = [], match.group(1)
    while text:
        digits = re.match(r"\d+", text)
        if not digits:
            break
        n = int(digits.group())
        start = digits.end()
        parts.append(text[start:start + n])
        text = text[start + n:]
    return ".".join(parts) if parts else symbol


_CHILD = f"""
import sys, time
import numpy as np
from abb_gym.benchmarks.env_speed import make_vector
from abb_gym.benchmarks.kernel_profile import write_perf_map
n, precision, seconds = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
scene, integrator = sys.argv[4], sys.argv[5]
env = make_vector(n, "specialised", integrator=integrator, precision=precision, scene=scene,
                  preset="train" if scene == "yoshida_odd" else "nominal")
env.reset(seed=0)
actions = np.random.default_rng(0).uniform(0.2, 1.0, (300, n, 1)).astype(np.float32)
for k in range(120):  # past an episode's end: the reset path compiles too
    env.step(actions[k])
path, count = write_perf_map()
print("{READY}", path, count, flush=True)
start = time.perf_counter()
steps = 0
while time.perf_counter() - start < seconds:
    for k in range(100):
        env.step(actions[k])
    steps += 100
rate = steps * n / (time.perf_counter() - start)
print(f"kernel_profile: {{rate:,.0f}} env-steps/s while profiled", flush=True)
"""


def _report(data: Path, sort: str) -> list[tuple[float, str]]:
    text = subprocess.run(["perf", "report", "-i", str(data), "--stdio", "--sort", sort],
                          capture_output=True, text=True, check=True).stdout
    rows = []
    for line in text.splitlines():
        match = re.match(r"\s*([\d.]+)%\s+(?:\[\.\]\s+|\[k\]\s+)?(.*\S)", line)
        if match and not line.lstrip().startswith("#"):
            rows.append((float(match.group(1)), match.group(2)))
    return rows


def profile(envs: int = 1024, precision: str = "float64", seconds: float = 8.0,
            top: int = 15, out: Path | None = None, scene: str = "yoshida_odd",
            integrator: str = "rk4") -> dict:
    """Profile the vector environment's steady state (module docstring); returns the rows
    ``{"libraries": [(percent, name)], "functions": [(percent, name)], "rate": str}``."""
    if not 1 <= envs <= 65536:
        raise ValueError(f"envs must be in [1, 65536] (got {envs})")
    if not 0.5 <= seconds <= 600:
        raise ValueError(f"seconds must be in [0.5, 600] (got {seconds})")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS} (got {precision!r})")
    if integrator not in COMPILED_METHODS:
        raise ValueError(f"integrator must be one of {COMPILED_METHODS} (got {integrator!r})")
    from ..physics.scene import list_scenes
    if scene not in list_scenes():
        raise ValueError(f"scene must be one of {list_scenes()} (got {scene!r})")
    if shutil.which("perf") is None:
        raise RuntimeError("kernel_profile needs Linux perf on the PATH (package linux-perf "
                           "or linux-tools)")
    work = Path(tempfile.mkdtemp(prefix="abb_gym_profile_"))
    data = Path(out) if out else work / "perf.data"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(work / "numba_cache"))
    print("kernel_profile: compiling the kernels in an empty cache (a minute or two) ...",
          file=sys.stderr, flush=True)
    child = subprocess.Popen([sys.executable, "-c", _CHILD, str(envs), precision,
                              str(seconds + 2.0), scene, integrator], env=env,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        for line in child.stdout:
            if line.startswith(READY):
                break
        else:
            raise RuntimeError("the profiled process ended before it was ready")
        subprocess.run(["perf", "record", "-q", "-F", "2000", "-o", str(data), "-p",
                        str(child.pid), "--", "sleep", str(seconds)], check=True,
                       stdout=subprocess.DEVNULL)
        rate = child.stdout.read().strip()
        child.wait(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
        shutil.rmtree(work / "numba_cache", ignore_errors=True)
    libraries = _report(data, "dso")
    functions = [(pct, readable_name(name)) for pct, name in _report(data, "sym")][:top]
    return {"libraries": libraries[:8], "functions": functions, "rate": rate,
            "data": str(data)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--envs", type=int, default=1024, help="sub-environments (default 1024)")
    ap.add_argument("--precision", choices=PRECISIONS, default="float64")
    ap.add_argument("--seconds", type=float, default=8.0, help="profiled time [s]")
    ap.add_argument("--top", type=int, default=15, help="functions to list")
    ap.add_argument("--scene", default="yoshida_odd",
                    help="scene (default yoshida_odd; others start from the nominal preset)")
    ap.add_argument("--integrator", default="rk4", help="integrator (default rk4)")
    args = ap.parse_args(argv)
    try:
        result = profile(args.envs, args.precision, args.seconds, args.top, scene=args.scene,
                         integrator=args.integrator)
    except (RuntimeError, ValueError) as exc:
        print(f"kernel_profile: {exc}", file=sys.stderr)
        return 2
    print(result["rate"])
    print("\nshare of all samples, by library:")
    for pct, name in result["libraries"]:
        print(f"  {pct:6.2f} %  {name}")
    print("\nby function (compiled functions by their Python names):")
    for pct, name in result["functions"]:
        print(f"  {pct:6.2f} %  {name}")
    print(f"\nperf data: {result['data']}  (perf report -i ... needs the map "
          f"/tmp/perf-<pid>.map, which stays)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

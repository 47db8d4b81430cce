"""Bit-identity of every packaged config's output, before and after a refactor.

Runs ``tolsim run`` on every file in ``configs/`` and the packaged default, seeded and with a
small sample, and either writes the netCDF files to a folder (``--write DIR``, keep it outside
the repository) or compares fresh runs against such a folder (``--compare DIR``). A comparison
checks every data variable and coordinate to the bit (NaNs in the same places), and every
attribute but the run's own stamps (``history``, ``date_created``, timings), and exits 1 on the
first difference it lists. A snapshot missing from the folder (a config added since) is
reported as new, not as a difference.

``tolsim allocate`` and ``tolsim carriage --json`` are snapshotted too, as text.

    python benchmarks/snapshot_outputs.py --write /tmp/snap-before
    ... refactor ...
    python benchmarks/snapshot_outputs.py --compare /tmp/snap-before
"""

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import xarray as xr

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs"
#: Assemblies per run: small, so the whole set runs in a few minutes.
SAMPLES = 256
SEED = 7
#: Attributes that stamp the run (time, machine), not the result.
RUN_STAMPS = ("history", "date_created", "elapsed", "wall", "seconds", "balls_per_second",
              "throughput", "resolve", "compile", "hostname", "sha256")


def _stamp(name: str) -> bool:
    return any(s in name for s in RUN_STAMPS)


def _runs():
    """(name, argv) of every snapshot."""
    out = [("default.nc", ["run"])]
    for path in sorted(CONFIGS.glob("*.toml")):
        text = path.read_text()
        if re.search(r"^\[allocate\]", text, re.M):
            out.append((path.stem + ".allocate.txt", ["allocate", str(path.relative_to(ROOT))]))
        out.append((path.stem + ".nc", ["run", str(path.relative_to(ROOT))]))
        if re.search(r"^\[carriage\]", text, re.M):
            out.append((path.stem + ".carriage.json",
                        ["carriage", str(path.relative_to(ROOT)), "--json"]))
    return out


def _run(argv, target: Path):
    cmd = [sys.executable, "-m", "tolsim", *argv]
    if argv[0] == "run":
        cmd += ["--samples", str(SAMPLES), "--seed", str(SEED), "-o", str(target), "--fresh"]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, cwd=ROOT)
    elif argv[0] == "allocate":
        with tempfile.TemporaryDirectory() as tmp:
            cmd += ["--samples", "1024", "--seed", str(SEED), "-o", tmp]
            subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
            files = sorted(f for f in Path(tmp).iterdir() if f.suffix in (".csv", ".json", ".toml"))
            text = "".join(f.read_text() for f in files).replace(tmp, "OUT")
            # timings are stamps of the run, not results
            target.write_text(re.sub(r"[0-9.]+ s\b", "T s", text))
    else:
        done = subprocess.run(cmd, check=True, capture_output=True, text=True, cwd=ROOT)
        target.write_text(done.stdout)


def _differences(a: Path, b: Path) -> list[str]:
    if a.suffix != ".nc":
        if a.suffix == ".json":
            return [] if json.loads(a.read_text()) == json.loads(b.read_text()) else ["text"]
        keep = [ln for ln in a.read_text().splitlines() if not _stamp(ln.lower())]
        new = [ln for ln in b.read_text().splitlines() if not _stamp(ln.lower())]
        return [] if keep == new else ["text"]
    out = []
    with xr.open_dataset(a, decode_cf=False) as x, xr.open_dataset(b, decode_cf=False) as y:
        for name in sorted(set(x.variables) | set(y.variables)):
            if name not in x.variables or name not in y.variables:
                out.append(f"{name}: only in one file")
                continue
            u, v = x[name].values, y[name].values
            if u.dtype != v.dtype or u.shape != v.shape:
                out.append(f"{name}: dtype/shape {u.dtype}{u.shape} vs {v.dtype}{v.shape}")
            elif u.dtype.kind in "fc":
                if not np.array_equal(np.ascontiguousarray(u).reshape(-1).view(np.uint8),
                                      np.ascontiguousarray(v).reshape(-1).view(np.uint8)):
                    out.append(f"{name}: values differ")
            elif not np.array_equal(u, v):
                out.append(f"{name}: values differ")
            for k in sorted(set(x[name].attrs) | set(y[name].attrs)):
                if not _stamp(k) and str(x[name].attrs.get(k)) != str(y[name].attrs.get(k)):
                    out.append(f"{name}.{k}: attribute differs")
        for k in sorted(set(x.attrs) | set(y.attrs)):
            if not _stamp(k) and str(x.attrs.get(k)) != str(y.attrs.get(k)):
                out.append(f".{k}: attribute differs")
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", type=Path, metavar="DIR", help="write the snapshots to DIR")
    g.add_argument("--compare", type=Path, metavar="DIR", help="compare fresh runs with DIR")
    p.add_argument("--only", nargs="*", default=None, help="snapshot names to run (stems)")
    args = p.parse_args(argv)
    runs = [(n, a) for n, a in _runs()
            if args.only is None or any(n.startswith(s) for s in args.only)]
    if args.write:
        args.write.mkdir(parents=True, exist_ok=True)
        for name, a in runs:
            _run(a, args.write / name)
            print(f"wrote {name}", flush=True)
        return 0
    failed = fresh = 0
    with tempfile.TemporaryDirectory() as tmp:
        for name, a in runs:
            new = Path(tmp) / name
            _run(a, new)
            if not (args.compare / name).exists():  # a config added since the snapshot
                fresh += 1
                print(f"new        {name} (runs; no snapshot in {args.compare} to compare)",
                      flush=True)
                continue
            diff = _differences(args.compare / name, new)
            failed += bool(diff)
            print(f"{'DIFFERS' if diff else 'identical'}  {name}", *diff[:10], sep="\n    ",
                  flush=True)
    print(f"{len(runs) - failed - fresh} of {len(runs) - fresh} identical"
          + (f", {fresh} new" if fresh else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""Step-size convergence of the along-track studies (tolsim issue 24, item 4).

For each config the study runs at several ``study.time_steps`` and at a fine-step reference,
with the same seed and samples (so the same assemblies: the comparison is paired), and the
script prints, per step count:

* P(contact) with its 95 % Clopper-Pearson interval, and whether the reference's P lies in
  that interval ("ok": the step-size error is smaller than the estimate's own statistical
  uncertainty);
* the paired change against the reference: assemblies that touch at this step and not at the
  reference (+) and the other way (-), and the mean |change| of the time to first contact
  over the assemblies that touch in both [s] (the step-size error of the integration, free
  of sampling noise), with its observed order between successive step counts n,
  log(err_1 / err_2) / log(n_2 / n_1) (2 for the midpoint rule on smooth epsilon);
* with ``[contact]`` (``--contact`` adds one where the config has none) the friction figures'
  means with their 95 % intervals (mean +- 1.96 s / sqrt(n)) and the same check;
* the median time to first contact over the assemblies that touch, with its 95 % interval
  (order statistics: the ranks of a binomial(k, 1/2) interval), and whether the reference's
  median lies in it;
* for an along-track carriage the fraction of first contacts at the zone's ends with its 95 %
  Clopper-Pearson interval over the contacts, and whether the reference's fraction lies in it,
  and with ``[carriage.circuit]`` the column forces at the zone's entry and exit (means over
  the assemblies of their stroke means [N]).

It drives the study only through config keys set in the config's text, which the loader
then validates (``study.time_steps``, and ``study.propagation = "along_track"`` for
configs/carriage_preload.toml, which is ``constant`` as packaged), and through the public
:func:`tolsim.run_study`, so it follows whatever step rule the integrator has.

``--steps auto`` runs the automatic step count (``study.time_steps = "auto"``,
:func:`tolsim.study.pipeline.propagation_rules.time_steps`), marked "a" in the table.
``--circuit`` adds a default ``[carriage.circuit]`` to a carriage config without one, and
``--relief DEPTH_UM LENGTH_MM`` sets the carriage's end relief (the variants the step rule's
Notes quote: ``--configs carriage_preload --circuit --relief 1 15``), and ``--preload UM`` its
preload oversize (0: the carriage without preload, whose balls are mostly two- and three-point,
Notes of :func:`tolsim.study.pipeline.propagation_rules.time_steps`).

Run: ``python benchmarks/convergence_along_track.py [--configs whatif_along_track
carriage_preload carriage_circuit] [--steps auto 25 50 100 200 400] [--reference 1600]
[--samples N] [--seed S] [--contact] [--circuit] [--relief DEPTH_UM LENGTH_MM] [--preload UM]``. The
defaults (800 assemblies) run in a few minutes on two idle cores; ``--samples`` sets the
size.
"""

import argparse
import math
import os
import re
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import binom

from tolsim import parse_config, run_study
from tolsim.io.schema.carriage import zone_end_counts, zone_end_fraction
from tolsim.study.pipeline.propagation_rules import time_steps as resolved_steps
from tolsim.study.spec import set_study_value
from tolsim.study.statistics.accumulator import clopper_pearson

ROOT = Path(__file__).resolve().parent.parent
#: The studies of the issue: free balls, the open carriage, the circuit.
CONFIGS = {
    "whatif_along_track": ROOT / "configs" / "whatif_along_track.toml",
    "carriage_preload": ROOT / "configs" / "carriage_preload.toml",
    "carriage_circuit": ROOT / "configs" / "carriage_circuit.toml",
}
STEPS = (25, 50, 100, 200, 400)
REFERENCE = 1600
#: Friction figures compared (names of :data:`tolsim.study.statistics.friction.COLUMNS`).
FRICTION_FIGURES = ("baseline", "increase_max", "increase_mean", "ripple")
#: z of the two-sided 95 % normal interval of a mean.
Z95 = 1.959963984540054


def with_study_keys(text: str, **keys) -> str:
    """The config ``text`` with ``[study]`` keys set (replaced where present, added after the
    ``[study]`` header otherwise; a ``[study]`` table is added if there is none)."""
    for key, value in keys.items():
        value = f'"{value}"' if isinstance(value, str) else value
        try:
            text = set_study_value(text, key, value)
        except ValueError:  # not in the text: add it to [study]
            header = re.search(r"^\s*\[study\]\s*(#.*)?$", text, flags=re.MULTILINE)
            if header is None:
                text = text.rstrip("\n") + f"\n\n[study]\n{key} = {value}\n"
            else:
                end = header.end()
                text = text[:end] + f"\n{key} = {value}" + text[end:]
    return text


def with_carriage_keys(text: str, **keys) -> str:
    """The config ``text`` with ``[carriage]`` keys set: a line ``key = ...`` replaced where
    the key is set, else added after the ``[carriage]`` header (ValueError without one)."""
    for key, value in keys.items():
        line = re.compile(rf"^{re.escape(key)}\s*=\s*[^#\n]*", flags=re.MULTILINE)
        if line.search(text):
            text = line.sub(f"{key} = {value} ", text, count=1)
            continue
        header = re.search(r"^\s*\[carriage\]\s*(#.*)?$", text, flags=re.MULTILINE)
        if header is None:
            raise ValueError(f"{key}: the config has no [carriage] table")
        text = text[:header.end()] + f"\n{key} = {value}" + text[header.end():]
    return text


def study_config(path, time_steps, *, samples=None, seed=None, contact=False, circuit=False,
                 relief=None, preload=None):
    """The study of ``path`` along the track at ``time_steps`` (an int, or ``"auto"``: the
    automatic count) (and ``samples``, ``seed`` if given), spot checks and sensitivity off,
    ``[contact]`` added if ``contact`` and the config has none, a default
    ``[carriage.circuit]`` if ``circuit`` and it has none, and the carriage's end relief
    ``relief`` = (depth [um], length [mm]) and preload oversize ``preload`` [um] if given."""
    text = Path(path).read_text(encoding="utf-8")
    if preload is not None:
        text = with_carriage_keys(text, preload_oversize_um=float(preload))
    if relief is not None:
        text = with_carriage_keys(text, end_relief_depth_um=float(relief[0]),
                                  end_relief_length_mm=float(relief[1]))
    if circuit and not re.search(r"^\s*\[carriage\.circuit\]", text, flags=re.MULTILINE):
        text = text.rstrip("\n") + "\n\n[carriage.circuit]\n"
    steps = "auto" if time_steps == "auto" else int(time_steps)
    keys = {"propagation": "along_track", "time_steps": steps, "spot_checks": 0,
            "sensitivity_samples": 0}
    if samples is not None:
        keys["samples"] = int(samples)
    if seed is not None:
        keys["seed"] = int(seed)
    text = with_study_keys(text, **keys)
    if contact and not re.search(r"^\s*\[contact\]", text, flags=re.MULTILINE):
        text = text.rstrip("\n") + "\n\n[contact]\n"
    return parse_config(text, str(path))


def steps_argument(text: str):
    """A ``--steps`` entry: ``"auto"`` or an integer."""
    return "auto" if text == "auto" else int(text)


def measure(config) -> dict:
    """Run the study and keep what the comparison needs."""
    samples = config.study.samples
    start = time.perf_counter()
    result = run_study(config, save_samples=samples)
    seconds = time.perf_counter() - start
    acc = result.statistics
    p, low, high = acc.contact_probability()
    out = {"time_steps": resolved_steps(config), "auto": config.study.time_steps is None,
           "p": p, "low": low, "high": high,
           "n_contact": int(acc.n_contact), "n_unresolved": int(acc.n_unresolved),
           "n": int(acc.n_assemblies), "seconds": seconds,
           "contact_time": np.asarray(result.samples["sample_contact_time"], dtype=float)}
    friction = result.friction
    if friction is not None:
        n = int(friction.count)
        out["friction"] = {name: (friction.column_mean(name),
                                  Z95 * friction.column_std(name) / math.sqrt(max(n, 1)))
                           for name in FRICTION_FIGURES}
    if config.carriage is not None and config.is_along_track:
        tracks, balls = config.n_tracks, config.train.balls
        counts = acc.pair_count[: tracks * max(balls - 1, 0)]
        out["zone_end_fraction"] = zone_end_fraction(counts, tracks)
        ends, total = zone_end_counts(counts, tracks)
        if total:
            out["zone_end_interval"] = clopper_pearson(ends, total)[1:]
        if acc.circuit is not None:
            c = acc.circuit
            count = max(int(c["circuit_count"]), 1)
            entry, exit_ = np.asarray(c["circuit_column_mean_sum"], dtype=float) / count
            out["column"] = {"entry": float(entry), "exit": float(exit_)}
    return out


def median_interval(times) -> tuple:
    """(median, low, high) of the finite ``times`` [s]: the sample median and its
    distribution-free 95 % interval, the order statistics of ranks l and k - l + 1 with l the
    2.5 % quantile of B ~ binomial(k, 1/2), which cover the population median with probability
    1 - 2 P(B < l) >= 0.95 (NaN ends for fewer than 6 times, which cannot give one)."""
    t = np.sort(np.asarray(times, dtype=float)[np.isfinite(times)])
    k = len(t)
    if k < 6:
        return (float(np.median(t)) if k else float("nan"), float("nan"), float("nan"))
    low = int(binom.ppf(0.025, k, 0.5))  # rank (1-based) of the lower end, at least 1
    high = int(k - low + 1)
    return float(np.median(t)), float(t[max(low, 1) - 1]), float(t[min(high, k) - 1])


def paired(row: dict, reference: dict) -> dict:
    """The paired change of ``row`` against ``reference`` (same assemblies): assemblies that
    touch only in the row (``gained``) or only in the reference (``lost``), and the mean
    |change| of the contact time over those that touch in both [s] (NaN if none)."""
    t, t_ref = row["contact_time"], reference["contact_time"]
    if t.shape != t_ref.shape:
        raise ValueError("the runs must have the same samples")
    hit, hit_ref = np.isfinite(t), np.isfinite(t_ref)
    both = hit & hit_ref
    change = float(np.mean(np.abs(t[both] - t_ref[both]))) if both.any() else float("nan")
    return {"gained": int(np.count_nonzero(hit & ~hit_ref)),
            "lost": int(np.count_nonzero(~hit & hit_ref)), "time_change": change}


def within(value: float, low: float, high: float) -> bool:
    """``value`` in [low, high] (the row's own 95 % interval)."""
    return bool(low <= value <= high)


def observed_order(errors, steps=None) -> list:
    """log(err_i / err_{i+1}) / log(n_{i+1} / n_i) between successive step counts n (log2 of
    the error ratio when ``steps`` is not given: counts that double; NaN where an error is 0
    or NaN, or the counts are equal); the first entry is NaN."""
    steps = [2.0**k for k in range(len(errors))] if steps is None else steps
    out = [float("nan")]
    for a, b, na, nb in zip(errors[:-1], errors[1:], steps[:-1], steps[1:], strict=True):
        ok = np.isfinite(a) and np.isfinite(b) and a > 0 and b > 0 and nb != na
        out.append(float(np.log(a / b) / np.log(nb / na)) if ok else float("nan"))
    return out


def compare(rows: list, reference: dict) -> list:
    """Per row (coarse step counts, in increasing order): the checks of the module docstring
    against ``reference``."""
    table = []
    for row in rows:
        entry = {"time_steps": row["time_steps"],
                 "p_ok": within(reference["p"], row["low"], row["high"]),
                 **paired(row, reference)}
        entry["median_ok"] = within(median_interval(reference["contact_time"])[0],
                                    *median_interval(row["contact_time"])[1:])
        if "zone_end_interval" in row and "zone_end_fraction" in reference:
            entry["ends_ok"] = within(reference["zone_end_fraction"], *row["zone_end_interval"])
        if "friction" in row:
            entry["friction_ok"] = {
                name: within(reference["friction"][name][0], mean - half, mean + half)
                for name, (mean, half) in row["friction"].items()}
        table.append(entry)
    orders = observed_order([e["time_change"] for e in table],
                            [e["time_steps"] for e in table])
    for entry, order in zip(table, orders, strict=True):
        entry["order"] = order
    return table


def _text(name, rows, reference, table) -> str:
    lines = [f"{name}: {reference['n']} assemblies, reference {reference['time_steps']} "
             f"steps ({reference['seconds']:.0f} s)",
             "  steps  P(contact) [95 %]           ref in it  +/- vs ref  "
             "mean|dt| [ms]  order  ends   column entry/exit [N]  s"]

    def line(row, entry):
        ok = "" if entry is None else ("yes" if entry["p_ok"] else "NO")
        pm = "" if entry is None else f"+{entry['gained']}/-{entry['lost']}"
        dt = "" if entry is None else f"{1e3 * entry['time_change']:.4g}"
        order = "" if entry is None or not np.isfinite(entry["order"]) else \
            f"{entry['order']:.2f}"
        ends = f"{row['zone_end_fraction']:.3f}" if "zone_end_fraction" in row else ""
        column = (f"{row['column']['entry']:.4f}/{row['column']['exit']:.4f}"
                  if "column" in row else "")
        steps = f"{row['time_steps']}{'a' if row.get('auto') else ''}"
        return (f"  {steps:>5}  {row['p']:.4f} [{row['low']:.4f}, "
                f"{row['high']:.4f}]  {ok:>9}  {pm:>10}  {dt:>13}  {order:>5}  {ends:>5}  "
                f"{column:>21}  {row['seconds']:.0f}")

    for row, entry in zip(rows, table, strict=True):
        lines.append(line(row, entry))
    lines.append(line(reference, None) + "   (reference)")
    lines.append("  time to first contact, median [95 %] [s]; fraction of first contacts at the "
                 "zone's ends [95 %]; reference in it:")
    for row, entry in [*zip(rows, table, strict=True), (reference, None)]:
        median, low, high = median_interval(row["contact_time"])
        parts = [f"median {median:.4g} [{low:.4g}, {high:.4g}]"
                 + ("" if entry is None else (" ok" if entry["median_ok"] else " NO"))]
        if "zone_end_interval" in row:
            low, high = row["zone_end_interval"]
            parts.append(f"ends {row['zone_end_fraction']:.3f} [{low:.3f}, {high:.3f}]"
                         + ("" if entry is None or "ends_ok" not in entry
                            else (" ok" if entry["ends_ok"] else " NO")))
        lines.append(f"  {row['time_steps']:>5}  " + "; ".join(parts))
    if "friction" in reference:
        lines.append("  friction figures [N], mean [95 %], reference in it:")
        for row, entry in [*zip(rows, table, strict=True), (reference, None)]:
            parts = []
            for figure, (mean, half) in row["friction"].items():
                ok = "" if entry is None else (" ok" if entry["friction_ok"][figure] else " NO")
                parts.append(f"{figure} {mean:.4g} [{mean - half:.4g}, {mean + half:.4g}]{ok}")
            lines.append(f"  {row['time_steps']:>5}  " + "; ".join(parts))
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument("--steps", nargs="+", type=steps_argument, default=list(STEPS),
                        help='step counts, or "auto" (the automatic count, marked "a")')
    parser.add_argument("--reference", type=int, default=REFERENCE,
                        help="time_steps of the fine-step reference")
    parser.add_argument("--samples", type=int, default=800)
    parser.add_argument("--seed", type=int, default=None, help="default: the config's")
    parser.add_argument("--contact", action="store_true",
                        help="add [contact] (friction figures) where the config has none and "
                             "allows it")
    parser.add_argument("--circuit", action="store_true",
                        help="add a default [carriage.circuit] to a carriage config without one")
    parser.add_argument("--relief", nargs=2, type=float, metavar=("DEPTH_UM", "LENGTH_MM"),
                        help="the carriage's end relief: depth [um] and length [mm]")
    parser.add_argument("--preload", type=float, metavar="UM",
                        help="the carriage's preload oversize [um] (0: no preload)")
    args = parser.parse_args(argv)
    numbers = [h for h in args.steps if h != "auto"]
    if (numbers and min(numbers) < 1) or any(h >= args.reference for h in numbers):
        parser.error("--steps must be >= 1 and below --reference")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"load average {load:.2f} at the start")
    for name in args.configs:
        path = CONFIGS[name]
        carriage = name != "whatif_along_track"
        variant = {"circuit": args.circuit and carriage,
                   "relief": args.relief if carriage else None,
                   "preload": args.preload if carriage else None}
        contact = args.contact
        name += "".join(
            [" + default [carriage.circuit]" if variant["circuit"] else ""]
            + ([f" + relief {args.relief[0]:g} um / {args.relief[1]:g} mm"]
               if variant["relief"] else [])
            + ([f" + preload {args.preload:g} um"] if variant["preload"] is not None else []))
        # warm-up: load or compile the kernels outside the timings
        run_study(study_config(path, 2, samples=1, seed=args.seed, contact=contact, **variant))
        rows = []
        reference = measure(study_config(path, args.reference, samples=args.samples,
                                         seed=args.seed, contact=contact, **variant))
        print(f"{name}: reference {args.reference} steps, P = {reference['p']:.4f} "
              f"({reference['seconds']:.0f} s)", flush=True)
        configs = [study_config(path, h, samples=args.samples, seed=args.seed, contact=contact,
                                **variant) for h in args.steps]
        for config in sorted(configs, key=resolved_steps):  # the table so far after each
            rows.append(measure(config))
            print(_text(name, rows, reference, compare(rows, reference)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

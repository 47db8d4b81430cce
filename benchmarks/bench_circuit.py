"""Throughput of the recirculating ball circuit step (tolsim.physics.circuit).

Prints, measured in this run, ball-steps per second (steps x balls / s) of:

* ``step_circuit_kernel`` called directly on preallocated arrays (all threads and 1 thread);
* the public :func:`tolsim.physics.circuit.step` (validation and copies included);
* the plain-NumPy twin of tests/physics/test_circuit.py (``reference_step``, vectorised over
  the balls, a Python loop over circuits and events) on the same circuits, and the ratio.

The circuits: 30 balls of 10 mm, 12 loaded (the circuit of the Notes of
``circuit_length``), slack 0.5 mm, epsilon ~ N(0, 1e-3), K ~ U(300, 700) N, drag 0.01 N, a
100 mm stroke in steps of 2 mm (about two contact events per circuit and step).

Run: ``python benchmarks/bench_circuit.py [--circuits M] [--steps S]``.
"""

import argparse
import pathlib
import sys
import time

import numba
import numpy as np

from tolsim.physics import circuit

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "physics"))
from test_circuit import random_circuits, reference_step  # noqa: E402  (the twin)


def kernel_arrays(state, eps, stiffness, capacity):
    m, n = state.position.shape
    return dict(
        position=state.position.copy(), diameter=state.diameter, eps=eps,
        stiffness=stiffness, pushed=np.zeros((m, n), dtype=bool), loaded=state.loaded.copy(),
        closed=state.closed.copy(),
        length=state.circuit_length, speed=state.speed.copy(), velocity=np.empty((m, n)),
        force=np.empty((m, n)), mean_force=np.empty((m, n)), column=np.empty((m, 4)),
        count=np.empty(m, dtype=np.int64), pair=np.empty((m, capacity), dtype=np.int64),
        where=np.empty((m, capacity), dtype=np.int8), when=np.empty((m, capacity)),
        status=np.empty(m, dtype=np.int64), crossing=np.empty((m, n)))


def run_kernel(a, zone, drag, ds, steps):
    events = 0
    start = time.perf_counter()
    for i in range(steps):
        circuit.step_circuit_kernel(
            a["position"], a["diameter"], a["eps"], a["stiffness"], a["pushed"], a["loaded"],
            a["closed"],
            a["length"], zone, drag, ds, i * ds, a["speed"], a["velocity"], a["force"],
            a["mean_force"], a["column"], a["count"], a["pair"], a["where"], a["when"],
            a["status"], *circuit.window_arrays(len(a["status"]), 0), a["crossing"])
        events += int(a["count"].sum())
    return time.perf_counter() - start, events


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--circuits", type=int, default=4000)
    parser.add_argument("--twin-circuits", type=int, default=40)
    parser.add_argument("--steps", type=int, default=50)
    args = parser.parse_args()
    drag, stroke = 0.01, 0.1
    ds = stroke / args.steps
    state, eps, stiffness = random_circuits(args.circuits, 2024)
    m, n = state.position.shape
    zone = state.zone_length
    # compile and warm up
    run_kernel(kernel_arrays(state, eps, stiffness, n), zone, drag, ds, 1)

    threads = numba.get_num_threads()
    seconds, events = run_kernel(kernel_arrays(state, eps, stiffness, n), zone, drag, ds,
                                 args.steps)
    numba.set_num_threads(1)
    seconds_1, _ = run_kernel(kernel_arrays(state, eps, stiffness, n), zone, drag, ds,
                              args.steps)
    numba.set_num_threads(threads)
    work = args.steps * m * n
    print(f"circuits {m} x {n} balls, {args.steps} steps of {ds * 1e3:g} mm, "
          f"{events / (m * args.steps):.2f} contact events per circuit and step")
    print(f"kernel, {threads} threads : {work / seconds:12.4g} ball-steps/s "
          f"({seconds * 1e6 / (args.steps * m):.2f} us per circuit-step)")
    print(f"kernel, 1 thread   : {work / seconds_1:12.4g} ball-steps/s")

    current = state
    start = time.perf_counter()
    for i in range(args.steps):
        current = circuit.step(current, eps, stiffness, ds, drag, travel_start=i * ds).state
    seconds_api = time.perf_counter() - start
    print(f"circuit.step       : {work / seconds_api:12.4g} ball-steps/s")

    mt = min(args.twin_circuits, m)
    twin_state = circuit.CircuitState(
        position=state.position[:mt], diameter=state.diameter[:mt], loaded=state.loaded[:mt],
        closed=state.closed[:mt], speed=state.speed[:mt],
        circuit_length=state.circuit_length[:mt], zone_length=zone)
    start = time.perf_counter()
    for i in range(args.steps):
        out = reference_step(twin_state, eps[:mt], stiffness[:mt], ds, drag, i * ds)
        twin_state = circuit.CircuitState(
            position=out["position"], diameter=twin_state.diameter, loaded=out["loaded"],
            closed=out["closed"], speed=out["speed"],
            circuit_length=twin_state.circuit_length, zone_length=zone)
    seconds_twin = time.perf_counter() - start
    twin_rate = args.steps * mt * n / seconds_twin
    print(f"NumPy twin ({mt} circuits): {twin_rate:12.4g} ball-steps/s")
    print(f"ratio kernel ({threads} threads) / twin: {work / seconds / twin_rate:.0f}x; "
          f"kernel (1 thread) / twin: {work / seconds_1 / twin_rate:.0f}x")


if __name__ == "__main__":
    main()

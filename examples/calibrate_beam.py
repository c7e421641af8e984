"""Calibration: recover the Young's modulus of scenes/beam.scn from a "measured" tip deflection.

The measurement protocol: release the cantilever from rest under gravity and read how far its tip
(DOF 98, the corner at x = 1) has dropped after 5 s. Here the "measurement" is a sofac run at a
known modulus, so the answer can be checked; with a real one, only ``measured`` changes.

1. A coarse sweep on Dask (``sofac.sweep``, a local cluster by default) over four decades of E
   brackets the measurement.
2. scipy.optimize.brentq refines E inside the bracket, each evaluation one sofac run of the scene
   compiled once (a new modulus needs no recompilation: it is a parameter of the compiled step, and
   ``reset()`` recomputes the element stiffnesses from it).

    python examples/calibrate_beam.py                 # local Dask cluster
    python examples/calibrate_beam.py --scheduler tcp://host:8786
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import sofac
from scipy.optimize import brentq

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "beam.scn"
MODULUS = "/beam/fem.youngModulus"
TIP = 98  # the free end's top corner
STEPS = 500  # 5 s at dt = 0.01: the beam has (nearly) settled


def tip_drop(sim: sofac.Simulation, modulus: float) -> float:
    """How far the tip has dropped after STEPS steps from rest, for this modulus."""
    sim.param(MODULUS)[0] = modulus
    sim.reset()  # back to rest; stiffnesses recomputed from the new modulus
    start = sim["dofs"].position[TIP, 1]
    sim.step(STEPS)
    return float(start - sim["dofs"].position[TIP, 1])


def calibrate(measured: float, scheduler: str | None = None) -> tuple[float, int]:
    """The modulus whose tip drop equals ``measured``, and the number of refinement runs."""
    coarse = sofac.sweep(
        SCENE,
        {MODULUS: np.geomspace(1e5, 1e9, 9).tolist()},
        steps=STEPS,
        record=[f"/beam/dofs.position[{TIP}]"],
        scheduler=scheduler,
    )
    moduli = coarse["beam.fem.youngModulus"].values
    y = coarse["beam.dofs.position"].values[:, :, 0, 1]  # runs x (first, last sample)
    drops = y[:, 0] - y[:, -1]
    print("coarse sweep on Dask:")
    for modulus, drop, status in zip(moduli, drops, coarse["status"].values, strict=True):
        print(f"  E = {modulus:9.3g} Pa   tip drop = {drop:.6f} m   {status}")
    # A stiffer beam drops less: the bracket is where the drops pass the measured value.
    above = np.flatnonzero(drops >= measured)
    if not above.size or above[-1] + 1 >= len(moduli):
        raise SystemExit(f"the measured drop {measured} m is outside the swept range")
    low, high = moduli[above[-1]], moduli[above[-1] + 1]

    sim = sofac.load(SCENE)
    runs = 0

    def mismatch(log_modulus: float) -> float:
        nonlocal runs
        runs += 1
        return tip_drop(sim, 10.0**log_modulus) - measured

    log_modulus = brentq(mismatch, math.log10(low), math.log10(high), xtol=1e-10, rtol=1e-12)
    return 10.0**log_modulus, runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--true-modulus", type=float, default=2.5e6, help="the modulus of the 'measurement'")
    parser.add_argument("--scheduler", help="a Dask scheduler address (default: a local cluster)")
    args = parser.parse_args()
    measured = tip_drop(sofac.load(SCENE), args.true_modulus)
    print(f'"measured" tip drop after {STEPS} steps: {measured:.6f} m')
    modulus, runs = calibrate(measured, args.scheduler)
    error = abs(modulus - args.true_modulus) / args.true_modulus
    print(f"recovered E = {modulus:.6g} Pa after {runs} refinement runs")
    print(f"true E      = {args.true_modulus:.6g} Pa (relative error {error:.1e})")


if __name__ == "__main__":
    main()

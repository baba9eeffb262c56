"""Regenerate the Siconos oracle ``two_contact_closed_theta*.csv.gz`` in this folder.

The 3-DOF, two-contact system of ``../shared/oracles/siconos/generated/two_contact_*``
(same M, C, K, W, gap offsets, e = 0.6, h = 1e-3) with a stronger constant force
``(-6, -5, 1)`` that preloads both contacts, over T = 2 s: about ten impacts on each
contact, then both contacts closed together on about 1200 steps — the coupled Delassus
matrix in persistent contact, which the shared ``two_contact_*`` runs (both contacts
closed together on 2 steps only) do not exercise. Run with the Python that has Siconos
(Debian ``python3-siconos``) from the project root::

    /usr/bin/python3 tests/data/siconos/make_two_contact_closed.py

It feeds each ``two_contact_closed_thetaX.json`` (the exact input, the format of the
shared generated oracles) to ``bench/siconos_driver.py`` (one Interaction per contact,
``MoreauJeanOSI(theta)``, Lemke) and writes ``two_contact_closed_thetaX.csv.gz``: header
``t,q0..,u0..,P0..``, one row per step, 17 significant digits.
"""

import gzip
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DRIVER = HERE.parents[2] / "bench" / "siconos_driver.py"
BASE = {
    "M": [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.5]],
    "C": [[0.4, -0.1, 0.0], [-0.1, 0.3, -0.1], [0.0, -0.1, 0.2]],
    "K": [[30.0, -10.0, 0.0], [-10.0, 25.0, -8.0], [0.0, -8.0, 12.0]],
    "W": [[1.0, 0.5], [0.0, 1.0], [-0.5, 0.0]],
    "forcing": {"constant": [-6.0, -5.0, 1.0], "amplitude": [2.0, 0.0, 1.0], "omega": 4.0,
                "phase": 0.3},
    "gap_offset": [0.08, 0.06], "restitution": 0.6, "q0": [0.0, 0.0, 0.0],
    "u0": [0.0, 0.0, 0.0], "h": 0.001, "T": 2.0,
}
THETAS = (0.5, 0.75, 1.0)


def main() -> None:
    for theta in THETAS:
        spec = dict(BASE, theta=theta)
        name = f"two_contact_closed_theta{theta}"
        (HERE / f"{name}.json").write_text(json.dumps(spec) + "\n")
        out = subprocess.run([sys.executable, str(DRIVER)], input=json.dumps(spec),
                             capture_output=True, text=True, check=True)
        run = json.loads(out.stdout.strip().splitlines()[-1])
        n, m = len(spec["M"]), len(spec["W"][0])
        header = ",".join(["t"] + [f"q{i}" for i in range(n)] + [f"u{i}" for i in range(n)]
                          + [f"P{j}" for j in range(m)])
        lines = [header]
        for k, t in enumerate(run["t"]):
            row = [t, *run["q"][k], *run["u"][k], *run["P"][k]]
            lines.append(",".join(f"{x:.17g}" for x in row))
        with gzip.open(HERE / f"{name}.csv.gz", "wt") as fh:
            fh.write("\n".join(lines) + "\n")
        print(name, run["siconos_version"], len(run["t"]), "rows")


if __name__ == "__main__":
    main()

"""A toy built-in scenario: a mass on a spring, forced against a wall (1 DOF, 1 contact)."""

DESCRIPTION = "toy: forced mass-spring against a wall"

PARAMETERS = dict(k=40.0, F=3.0, omega=5.0, restitution=0.5, law="newton", h=1e-3, t_end=0.6)

SUITE = {
    "observers": [dict(label="toy", h=(1e-3, 1e-3), t_end=(0.6, 0.6))],
    "work_precision": dict(h0=4e-3, t_end=0.2, targets=("master",)),
    "checks": "quick",
}


def document(**overrides) -> dict:
    p = {**PARAMETERS, **overrides}
    return {
        "system": {"M": [[1.0]], "C": [[0.4]], "K": [[p["k"]]], "W": [[-1.0]],
                   "forcing": {"constant": [0.0], "amplitude": [p["F"]], "omega": p["omega"]},
                   "gap": {"offset": [0.05]}},
        "impact": {"law": p["law"], "restitution": p["restitution"]},
        "initial": {"q": [0.0], "u": [0.5]},
        "simulation": {"t_end": p["t_end"], "h": p["h"]},
        "observer": {"q": [0.02], "u": [0.0], "observers": ["jump", "nojump"]},
    }

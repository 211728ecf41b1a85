"""The reference's own discretisation error, expressed as an effective Young's modulus.

A mesh of linear hexahedra is stiffer than the continuum it approximates (and lumping its mass
makes it a little softer again). With the Poisson ratio fixed, every eigenfrequency of a linear
elastic body scales exactly as sqrt(E). So if the mesh that produced a capture vibrates at f_h
where the continuum vibrates at f_inf, that mesh behaves like the continuum with

    E_eff,h = E_nominal * (f_h / f_inf)^2,

and a perfectly converged inverse solver fitted to the capture should return E_eff,h, not
E_nominal. We compute:

1. f at three meshes (coarse x1, x2, x3 per axis) with *FREQUENCY (consistent mass), the lowest
   elastic mode; the observed convergence order p from the three; f_inf by Richardson
   extrapolation of the two finest with that p (p = 2, the theoretical order of eigenvalues of
   trilinear elements, when the observed one is implausible).
2. f_h of each mesh that ran a motion, measured by a ringdown: the same explicit, lumped-mass
   scheme as the motion, started along the mode shape, fitted with a sinusoid.
3. scale_h = (f_h / f_inf)^2 and E_eff,h = scale_h * E for each material.

The consistent-mass scales are reported too, and the scales of the next few modes, to show how
much "one effective E" is an approximation for a motion that excites several modes.
"""

import os

import numpy as np

from . import ccx_deck, ccx_run

FREQUENCY_LEVELS = (1, 2, 3)  # refinement factors of the coarse mesh for the *FREQUENCY study


def _rigid_mode_count(model):
    return 0 if len(model.clamped_nodes) else 6


def frequency_level(case, settings, factor, workdir):
    """Elastic eigenfrequencies [Hz] and mode shapes of the mesh refined by `factor`."""
    model = ccx_deck.build_model(case, case.divisions_at(factor))
    directory = os.path.join(workdir, f"frequency-x{factor}")
    seconds = ccx_run.run(ccx_deck.frequency_deck(case, model, settings), directory, "frequency")
    dat = os.path.join(directory, "frequency.dat")
    rigid = _rigid_mode_count(model)
    frequencies = ccx_run.read_eigenfrequencies(dat)[rigid:]
    shapes = [u for _, u in ccx_run.read_displacements(dat, model.mesh.node_count)][rigid:]
    return {"factor": factor, "divisions": list(model.mesh.divisions),
            "element_size_m": float(model.mesh.element_size.max()), "frequencies_hz": frequencies,
            "shapes": shapes, "seconds": seconds, "model": model}


def observed_order(f1, f2, f3, r12=2.0, r13=3.0):
    """Order p of f_h = f_inf + C h^p from meshes h, h/r12, h/r13 (bisection), or None."""
    def mismatch(p):
        # (f1 - f2) / (f2 - f3) as predicted by C h^p, minus the observed ratio
        predicted = (1 - r12 ** -p) / (r12 ** -p - r13 ** -p)
        return predicted - (f1 - f2) / (f2 - f3)
    if (f1 - f2) * (f2 - f3) <= 0:
        return None  # not monotone: outside the asymptotic range
    lo, hi = 0.25, 8.0
    if mismatch(lo) * mismatch(hi) > 0:
        return None
    for _ in range(100):
        mid = (lo + hi) / 2
        if mismatch(lo) * mismatch(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return (lo + hi) / 2


def richardson(f_coarse, f_fine, ratio, order):
    return f_fine + (f_fine - f_coarse) / (ratio ** order - 1)


def fit_frequency(times, signal, guess):
    """Frequency [Hz] of the best least-squares fit a sin + b cos + c + d t, searched near guess."""
    def residual(f):
        w = 2 * np.pi * f
        basis = np.stack([np.sin(w * times), np.cos(w * times), np.ones_like(times), times], axis=1)
        coefficients, *_ = np.linalg.lstsq(basis, signal, rcond=None)
        return float(np.sum((basis @ coefficients - signal) ** 2))
    grid = np.linspace(0.7 * guess, 1.3 * guess, 601)
    best = grid[np.argmin([residual(f) for f in grid])]
    lo, hi = best - (grid[1] - grid[0]), best + (grid[1] - grid[0])
    golden = (np.sqrt(5) - 1) / 2
    for _ in range(60):  # golden-section refinement on the bracketing interval
        a, b = hi - golden * (hi - lo), lo + golden * (hi - lo)
        if residual(a) < residual(b):
            hi = b
        else:
            lo = a
    return (lo + hi) / 2


def ringdown(case, settings, level, workdir):
    """The lowest elastic mode's frequency [Hz] of this mesh under the explicit scheme."""
    model, shape, guess = level["model"], level["shapes"][0], level["frequencies_hz"][0]
    deck, _ = ccx_deck.ringdown_deck(case, model, settings, shape, guess)
    directory = os.path.join(workdir, f"ringdown-x{level['factor']}")
    seconds = ccx_run.run(deck, directory, "ringdown")
    frames = ccx_run.read_displacements(os.path.join(directory, "ringdown.dat"), model.mesh.node_count)
    times = np.array([t for t, _ in frames])
    signal = np.array([np.sum(u * shape) for _, u in frames])
    return fit_frequency(times, signal, guess), seconds


def study(case, settings, workdir, dynamic_factors):
    """The effective-stiffness record for truth.json's "reference" (see the module docstring)."""
    levels = [frequency_level(case, settings, factor, workdir) for factor in FREQUENCY_LEVELS]
    lowest = [float(level["frequencies_hz"][0]) for level in levels]
    p = observed_order(*lowest)
    order = p if p is not None and 1.0 <= p <= 4.0 else 2.0
    f_inf = richardson(lowest[1], lowest[2], 3.0 / 2.0, order)
    record = {
        "method": "E_eff = E_nominal * (f_h / f_inf)^2, f: lowest elastic eigenfrequency "
                  "(tools/validation/softid_validation/stiffness.py)",
        "frequency_study": [
            {"refinement": level["factor"], "divisions": level["divisions"],
             "element_size_m": level["element_size_m"],
             "frequencies_hz": [float(f) for f in level["frequencies_hz"][:5]],
             "ccx_seconds": round(level["seconds"], 2)} for level in levels],
        "observed_order": p,
        "order_used": order,
        "frequency_extrapolated_hz": f_inf,
        "extrapolation_change": f_inf / lowest[2] - 1.0,
        "consistent_mass_scale": {f"x{lv['factor']}": (f / f_inf) ** 2 for lv, f in zip(levels, lowest)},
        "meshes": {},
    }
    # Next modes: their own extrapolations, to show the spread of "one effective E".
    modes = min(len(levels[1]["frequencies_hz"]), len(levels[2]["frequencies_hz"]), 5)
    f_inf_modes = [richardson(levels[1]["frequencies_hz"][m], levels[2]["frequencies_hz"][m], 1.5, order)
                   for m in range(modes)]
    for factor in dynamic_factors:
        level = next(lv for lv in levels if lv["factor"] == factor)
        f_h, seconds = ringdown(case, settings, level, workdir)
        scale = (f_h / f_inf) ** 2
        mode_scales = [(level["frequencies_hz"][m] / f_inf_modes[m]) ** 2 for m in range(modes)]
        record["meshes"][f"x{factor}"] = {
            "divisions": level["divisions"],
            "ringdown_frequency_hz": f_h,
            "ringdown_ccx_seconds": round(seconds, 2),
            "stiffness_scale": scale,
            "consistent_mass_scales_of_modes_1_to_5": mode_scales,
            "effective_youngs_modulus": [scale * m.youngs_modulus for m in _materials(case)],
        }
    return record


def _materials(case):
    return [case.material] + ([case.second_material] if case.second_material else [])

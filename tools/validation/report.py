#!/usr/bin/python3
"""Prints the reference table of a generated validation set (OUT/summary.json) as Markdown.

    tools/validation/report.py OUT
"""

import json
import os
import sys


def fmt_e(values):
    return " / ".join(f"{v / 1e3:.2f}" for v in values)


def main(argv):
    if len(argv) != 2:
        print(__doc__.split("\n\n")[1].strip(), file=sys.stderr)
        return 2
    with open(os.path.join(argv[1], "summary.json")) as f:
        summaries = json.load(f)["cases"]
    print("| case | E nominal [kPa] | E_eff coarse [kPa] | E_eff fine [kPa] | f_inf [Hz] | order p "
          "| ccx motion coarse / fine [s] | coarse-fine surface distance RMS / max [mm] |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for s in summaries:
        captures = s["captures"]
        e_eff = {r: fmt_e(c["effective_youngs_modulus"]) for r, c in captures.items()}
        seconds = " / ".join(f"{captures[r]['ccx_seconds']:.0f}" if r in captures else "-"
                             for r in ("coarse", "fine"))
        distance = s.get("coarse_to_fine_surface_distance")
        distance = (f"{distance['rms_m'] * 1e3:.1f} / {distance['max_m'] * 1e3:.1f}"
                    if distance else "-")
        order = f"{s['observed_order']:.2f}" if s["observed_order"] is not None else "-"
        print(f"| `{s['case']}` | {fmt_e(s['nominal_youngs_modulus'])} | {e_eff.get('coarse', '-')} "
              f"| {e_eff.get('fine', '-')} | {s['frequency_extrapolated_hz']:.3f} | {order} "
              f"| {seconds} | {distance} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

"""The real robot's turning circles (dissertation Appendix D) against the set-point prediction, as a
table, and the track fit's sweep: ``python -m tools.appendix_d [table] [fit]`` from the repository root
(:mod:`skidsteer_power.models.appendix_d` computes; the models take no command line, issue 38)."""

from __future__ import annotations

import argparse

from skidsteer_power.models.appendix_d import check, fit_track_shear_ratio, summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m tools.appendix_d')
    parser.add_argument('what', nargs='*', choices=('table', 'fit'), default=['table'])
    args = parser.parse_args(argv)
    if 'table' in args.what:
        rows = check()
        print('vehicle | V cmd | yaw cmd | R cmd | R real | R FESS set points | R pred / R real - 1')
        for r in rows:
            c = r.cell
            radii = f'{c.commanded_radius_m:.2f} | {c.radius_m:.2f} | {r.radius_m:.2f}'
            print(f'{c.vehicle} | {c.speed_cmd:g} | {c.yaw_cmd:g} | {radii} | '
                  f'{100 * (r.radius_m / c.radius_m - 1):+.1f} %')  # fmt: skip
        result = summary(rows)
        print(f'median {100 * result["median_error"]:.1f} %, max {100 * result["max_error"]:.1f} %')
    if 'fit' in args.what:
        for ratio, median, worst in fit_track_shear_ratio():
            print(f'K_x / K = {ratio:g}: median {100 * median:.1f} %, max {100 * worst:.1f} %', flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

"""Synthetic light-field generation speed (target: a 7x7x128x128 sample in
<= 50 ms on a 2-core CPU, for on-the-fly training data), plus larger sizes.

    python bench/synth.py [--json [FILE]] [--runs N] [--quick]
"""

from __future__ import annotations

from _harness import emit, parser, timeit

from lfstream.synth import synth_clip


def main(argv=None) -> dict:
    args = parser(__doc__).parse_args(argv)
    runs = 3 if args.quick else args.runs
    cases = [("7x7x128x128", dict(views=7, size=(128, 128))),
             ("7x7x128x128 noise+vignetting", dict(views=7, size=(128, 128), noise=2.0, vignetting=0.3))]
    if not args.quick:
        cases.append(("7x7x375x540", dict(views=7, size=(375, 540))))
    results = []
    seeds = iter(range(10**6))
    for name, kw in cases:
        # a new seed per call: every sample is a different scene, as in training
        r = {"name": name, **timeit(lambda: synth_clip(1, seed=next(seeds), **kw), runs=runs)}
        if name == "7x7x128x128":
            r["target_s"] = 0.05
            r["meets_target"] = r["median_s"] <= 0.05
        results.append(r)
        print(f"{name:32s} {r['median_s'] * 1000:8.1f} ms (IQR {r['iqr_s'] * 1000:.1f} ms)")
    return emit(args, results)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Side-by-side samples/s of several `tessera` binaries, interleaved so that they share the
machine's noise: each round runs every binary on every scene once
(`bench speed --threads 1 --spp 16 --repeats 2`), and the best samples per CPU-second of
each (binary, scene) over the rounds is compared with the first binary.

    scripts/speed-compare.py OLD_TESSERA,NEW_TESSERA [--integrator pt] [--rounds 3] SCENE...
"""

import argparse
import json
import math
import subprocess


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("binaries", help="comma-separated tessera executables; the first is the reference")
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--integrator", default="pt")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    exes = args.binaries.split(",")
    best = {(e, s): 0.0 for e in exes for s in args.scenes}
    for _ in range(args.rounds):
        for s in args.scenes:
            for e in exes:
                cmd = [e, "bench", "speed", "--threads", "1", "--spp", "16", "--repeats", "2",
                       "--integrator", args.integrator, "--json", s]
                out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
                for line in out.splitlines():
                    if line.startswith("{"):
                        best[(e, s)] = max(best[(e, s)], json.loads(line)["tessera"]["samples_per_cpu_s"])
    for s in args.scenes:
        ref = best[(exes[0], s)]
        print(s, "  ".join(f"{e}: {best[(e, s)]:.0f} ({best[(e, s)] / ref:.3f})" for e in exes))
    for e in exes[1:]:
        g = math.exp(sum(math.log(best[(e, s)] / best[(exes[0], s)]) for s in args.scenes) / len(args.scenes))
        print(f"geometric mean {e} / {exes[0]}: {g:.3f}")


if __name__ == "__main__":
    main()

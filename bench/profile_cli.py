"""Profile one plain-CLI command's driver (its main thread) with cProfile: `python bench/profile_cli.py OUT.txt
[MODULE.NAME=VALUE ...] -- piezotwin-args...` (a module-level constant may be set first, for an A/B, e.g.
simulate.generation.feed.RAMP_BATCHES=0). Writes the 60 heaviest calls by cumulative time, then by own time."""

from __future__ import annotations

import cProfile
import importlib
import io
import pstats
import sys
import time


def main() -> None:
    out, rest = sys.argv[1], sys.argv[2:]
    cut = rest.index("--")
    for assign in rest[:cut]:
        name, value = assign.split("=", 1)
        mod, attr = name.rsplit(".", 1)
        setattr(importlib.import_module(mod), attr, type(getattr(importlib.import_module(mod), attr))(value))
    sys.argv = ["piezotwin", *rest[cut + 1:]]
    from piezotwin.cli import main as cli

    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    try:
        cli()
    except SystemExit:
        pass
    prof.disable()
    wall = time.perf_counter() - t0
    buf = io.StringIO()
    buf.write(f"wall {wall:.2f} s; {' '.join(rest)}\n")
    from simulate.generation.feed import LAST_RUN_SECONDS

    buf.write("feed: " + "; ".join(f"{k} {v:.2f} s" for k, v in LAST_RUN_SECONDS.items()) + "\n")
    for key in ("cumulative", "tottime"):
        pstats.Stats(prof, stream=buf).sort_stats(key).print_stats(60)
    open(out, "w").write(buf.getvalue())
    print(f"wall {wall:.2f} s -> {out}")


if __name__ == "__main__":
    main()

"""The machine's own scaling ceiling: a pure-Python CPU kernel alone vs N copies at once.

    python bench/bench_cpu_ceiling.py [--copies 2]

If N concurrent copies each run slower than one alone, no evaluation runner can scale linearly on
this machine; the ratio bounds what ``--workers N`` can reach.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time


def kernel(n: int = 30_000_000) -> float:
    t = time.perf_counter()
    x = 0
    for i in range(n):
        x += i * i
    return time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=2)
    args = parser.parse_args()
    alone = kernel()
    with mp.get_context("spawn").Pool(args.copies) as pool:
        together = pool.starmap(kernel, [()] * args.copies)
    ceiling = args.copies * alone / max(together)
    print(
        f"alone {alone:.2f} s; {args.copies} at once: {', '.join(f'{t:.2f}' for t in together)} s; "
        f"throughput ceiling {ceiling:.2f}x (ideal {args.copies}x)"
    )


if __name__ == "__main__":
    main()

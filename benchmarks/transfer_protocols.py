"""Run the synthetic evaluation protocols and print their cost and the full-vs-ablation outcome.

    OMP_NUM_THREADS=1 python benchmarks/transfer_protocols.py --world WORLD --shapes SHAPES --checkpoint GAN \\
        --pose-checkpoint POSE --noc-checkpoint NOC [--latent-iters 20] [--refine-iters 20] [--queries 4] [--only
        known_pose] [--out DIR]

Prints, per transfer protocol and row (ablations and baselines): seconds in all, for ablations the
seconds per transfer iteration and the time relative to the full method in the same run, and how
many columns the full method wins against each row (ties counted apart); and the columns the
oracle does not win, if any. The metrics themselves are in OUT/protocols.md.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.evaluation.protocol_config import ProtocolConfig  # noqa: E402
from mesh2tex.evaluation.protocols import run_protocols  # noqa: E402
from mesh2tex.evaluation.report import PROTOCOLS  # noqa: E402
from mesh2tex.transfer import ABLATIONS  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", required=True)
    parser.add_argument("--shapes", required=True)
    # named as 'mesh2tex evaluate --protocols' names them (the former --gan, --pose, --noc still work)
    parser.add_argument(
        "--checkpoint",
        "--gan",
        dest="checkpoint",
        required=True,
        help="generator: a checkpoint or a shipped model's name",
    )
    parser.add_argument("--pose-checkpoint", "--pose", dest="pose", required=True)
    parser.add_argument("--noc-checkpoint", "--noc", dest="noc", required=True)
    parser.add_argument("--latent-iters", type=int, default=20)
    parser.add_argument("--refine-iters", type=int, default=20)
    parser.add_argument("--queries", type=int, default=0)
    parser.add_argument("--only", default=",".join(PROTOCOLS))
    parser.add_argument("--out", help="keep protocols.json/.md and renders here (default: a temporary folder)")
    args = parser.parse_args()
    transfer = replace(ProtocolConfig().transfer, latent_iters=args.latent_iters, refine_iters=args.refine_iters)
    cfg = ProtocolConfig(protocols=args.only.split(","), queries=args.queries, device="cpu", transfer=transfer)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="protocols_"))
    result = run_protocols(
        args.world, args.shapes, args.checkpoint, args.pose, args.noc, cfg, out, log=lambda line: None
    )
    queries = result["counts"]["queries"]
    print(
        f"{queries} queries, {cfg.transfer.latent_iters} + {cfg.transfer.refine_iters} iterations at {cfg.resolution} "
        f"px; results in {out}"
    )
    for name, entry in result["protocols"].items():
        print(f"{name}: {entry['seconds']:.1f} s")
        if "methods" not in entry:
            continue
        methods = entry["methods"]
        full_seconds = methods.get("full", {}).get("seconds")
        for method, row in methods.items():
            if method in ABLATIONS:
                iters = cfg.transfer.latent_iters + (cfg.transfer.refine_iters if method != "no_refine" else 0)
                cost = f", {row['seconds'] / max(queries * iters, 1):.3f} s/iteration"
                cost += f", x{row['seconds'] / full_seconds:.2f} of full" if full_seconds else ""
            else:
                cost = " (baseline, no optimisation)"
            wins = result["comparison"][name].get(method)
            outcome = f"; full wins {wins['wins']}/{wins['metrics']} columns (ties {wins['ties']})" if wins else ""
            print(f"  {method:<15} {row['seconds']:7.1f} s{cost}{outcome}")
        if entry.get("oracle_loses"):
            print(f"  the oracle does not win: {', '.join(entry['oracle_loses'])}")


if __name__ == "__main__":
    main()

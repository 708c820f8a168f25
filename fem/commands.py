"""The FEM's commands on the ``stmpl`` command line (entry-point group ``stmpl.commands``):
``stmpl generate CONFIG`` makes a dataset.
"""

from __future__ import annotations

from fem.generate import generate


def add_generate(sub) -> None:
    """Add ``generate`` to the ``stmpl`` subcommands ``sub`` (an argparse subparsers object)."""
    ge = sub.add_parser("generate", help="generate a FEM dataset from a config (resumable)")
    ge.add_argument("config", help="dataset config (YAML), e.g. configs/data/small.yaml")
    ge.add_argument("--out", help="output folder (default data/<config name>)")
    ge.add_argument("--workers", type=int, help="parallel workers (default from the config)")
    ge.add_argument("--backend", choices=["serial", "processes", "dask"])
    ge.add_argument("--scheduler", help="Dask scheduler address (implies --backend dask)")
    ge.add_argument("--max-shards", type=int, help="stop after this many new shards")
    ge.add_argument(
        "--max-bodies", type=int, help="a config of several bodies: stop after the first this many"
    )
    ge.add_argument("--quiet", action="store_true", help="no progress bar")
    ge.set_defaults(func=generate_command)


def generate_command(args) -> int:

    card = generate(
        args.config,
        args.out,
        workers=args.workers,
        backend=args.backend,
        scheduler=args.scheduler,
        progress=not args.quiet,
        max_shards=args.max_shards,
        max_bodies=args.max_bodies,
    )
    if not card:
        print("stopped early (--max-shards or --max-bodies); run again to finish")
        return 0
    if "members" in card:  # one dataset per body
        for m in card["members"]:
            sp = m["samples_per_split"]
            print(
                f"{m['folder']}: {m['samples']} samples (train {sp['train']}, val "
                f"{sp['val']}, test {sp['test']}), {m['failures']} solves failed; "
                f"{m['thickness_mm'][0]:g} mm, {m['phenotype']}"
            )
        print(
            f"{card['samples']} samples on {len(card['members'])} bodies; content hash "
            f"{card['hash']}"
        )
        return 0
    sp = card["samples_per_split"]
    median = card["timing"]["solve_seconds_median_per_sample"]
    print(
        f"{card['samples']} samples (train {sp['train']}, val {sp['val']}, test "
        f"{sp['test']}) from {card['placements']} placements; {card['failures']} of "
        f"{card['attempted']} solves failed {card['failures_by_reason'] or ''}"
        + (f"; median {median:.2f} s per sample" if median is not None else "")
    )
    skipped = card.get("placements_skipped", {}).get("count", 0)
    if skipped:
        print(
            f"{skipped} placements left out before solving "
            f"{card['placements_skipped']['by_reason']}"
        )
    print(f"content hash {card['hash']}")
    return 0

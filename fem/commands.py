"""The FEM's commands on the ``stmpl`` command line (declared in :mod:`fem.arguments`):
``stmpl generate CONFIG`` makes a dataset; ``stmpl solve`` solves one primitive scene and draws
it with a section through the tissue shell.
"""

from __future__ import annotations

from fem.generate import generate
from fem.pictures import deformation_figure
from fem.predictor import FEMPredictor
from stmpl.cli.arguments import TISSUE
from stmpl.cli.options import phenotype_of, scene_of


def generate_command(args) -> int:
    """``stmpl generate``: make (or finish) a dataset and sum it up."""
    card = generate(
        args.config,
        args.out,
        workers=args.workers,
        backend=args.backend,
        scheduler=args.scheduler,
        progress=not args.quiet,
        max_shards=args.max_shards,
        max_bodies=args.max_bodies,
        tissue=args.tissue,
    )
    if not card:
        print("stopped early (--max-bodies); run again to finish")
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
        f"{card['attempted']} solves failed"
        + (f" {card['failures_by_reason']}" if card["failures_by_reason"] else "")
        + (f"; median {median:.2f} s per sample" if median is not None else "")
    )
    skipped = card.get("placements_skipped", {}).get("count", 0)
    if skipped:
        print(
            f"{skipped} placements left out before solving "
            f"{card['placements_skipped']['by_reason']}"
        )
    print(f"content hash {card['hash']}")
    if not card["complete"]:
        print(
            f"stopped early: {card['shards_written']} shards ({card['tasks']} of "
            f"{card['tasks_planned']} tasks); the card says the set is not complete; run again "
            "to finish it"
        )
    return 0


def solve_command(args) -> int:
    """``stmpl solve``: the FEM's answer, each continuation level printed; a failed solve raises
    with its reason.
    """
    scene = scene_of(args)
    fem = FEMPredictor(
        res=args.res, levels=args.levels, tissue=args.tissue or TISSUE, phenotype=phenotype_of(args)
    )
    d = fem.predict(scene)
    shell = fem.last_shell
    print(
        f"shell: {d.info['mesh']['nodes']} nodes, {d.info['mesh']['tets']} tets ({args.res}, "
        f"{args.tissue or TISSUE}); {shell.mesh.quality()}"
    )
    for s in d.info["levels"]:
        print(
            f"  {s['total_force']:6.3f} N  ok  {s['iterations']} Newton steps  "
            f"max |u| {1e3 * s['max_displacement']:.2f} mm  {s['time']:.2f} s"
        )
    if args.out:
        deformation_figure(
            d, shell.mesh.nodes, shell.mesh.tets, shell.displacement, args.out, size=args.size
        )
        print(f"wrote {args.out}")
    if args.save:
        d.save(args.save)
        print(f"wrote {args.save}")
    if args.vtu:
        shell.mesh.to_vtu(args.vtu, point_data={"displacement": shell.displacement})
        print(f"wrote {args.vtu}")
    return 0

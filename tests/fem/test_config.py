"""The dataset config: what it refuses, by name, before anything is solved."""

import numpy as np
import pytest

from fem.config import read_config
from fem.generate import generate
from fem.placements import plan


def _cfg(**over):
    cfg = {
        "name": "tiny",
        "body": {"model": "tube", "radius": 0.04, "length": 0.2, "n_around": 16, "n_along": 12},
        "part": "tube",
        "thickness_mm": [5.0],
        "forces": [0.05, 0.1],
        "resolution": {"subdivisions": 1, "layers": 1, "refine_radius": 0.03, "order": 1},
        "placements": {"disk": {"centres": 4, "radii": [0.02]}},
        "parallel": {"backend": "serial", "workers": 1},
    }
    cfg.update(over)
    return cfg


@pytest.mark.parametrize(
    "over,message",
    [
        ({"max_pressure": True}, "max_pressure must be a number > 0 Pa, got True"),
        ({"max_pressure": -5}, "max_pressure must be a number > 0"),
        ({"shard_tasks": True}, "shard_tasks must be an integer >= 1"),
        ({"seed": 1.5}, "seed must be an integer"),
        ({"forces": [0.1, True]}, "forces must be a non-empty list of numbers"),
        ({"placements": {"disk": {"centres": 2.5}}}, "placements.disk.centres must be an integer"),
        (
            {"placements": {"letter": {"uv": [0.5, 0.5]}}},
            r"placements.letter.uv must be a non-empty list of \[a, b\] pairs",
        ),
        (
            {"placements": {"letter": {"heights": [float("nan")]}}},
            "placements.letter.heights must be a non-empty list of numbers, got .nan",
        ),
        ({"placements": {"disk": {"radii": ["5 mm"]}}}, "placements.disk.radii must be"),
        ({"placements": {"grasp": {"grips": [""]}}}, "placements.grasp.grips must be"),
        ({"placements": {"spots": {"counts": [0]}}}, "placements.spots.counts must be"),
        ({"placements": {"palm": {"depth": "2"}}}, "placements.palm.depth must be a number"),
        ({"parallel": {"backend": "threads"}}, "parallel.backend must be one of"),
        ({"parallel": {"workers": 0}}, "parallel.workers must be an integer >= 1"),
        ({"body": {"model": "tube", "radius": 0.04, "colour": "red"}}, "unknown body keys"),
        ({"material": {"name": "neo_hookean", "G": 3}}, "material:"),
        ({"solver": {"load": "nodal"}}, "solver:"),
        ({"placements": {"disk": {"centres": 4, "skip": 4}}}, "skip 4 leaves none of its 4"),
        ({"placements": {"disk": {"skip": -1}}}, "placements.disk.skip must be an integer >= 0"),
        ({"thickness_cycle": "yes"}, "thickness_cycle must be true or false"),
        ({"force_tolerance": 0.5}, r"force_tolerance must be a share of each force in \(0, 0.5\)"),
        ({"force_tolerance": True}, "force_tolerance must be a share"),
        ({"force_tolerance": 0.2}, "force_tolerance 0.2: only pressed objects"),
    ],
)
def test_bad_values_are_named(over, message):
    with pytest.raises(ValueError, match=message):
        read_config(_cfg(**over))


def test_broken_yaml_is_named(tmp_path):
    f = tmp_path / "broken.yaml"
    f.write_text("name: x\nforces: [0.1, 0.2\n")
    with pytest.raises(ValueError, match="broken.yaml is not valid YAML"):
        read_config(f)
    f.write_text("- a\n- list\n")
    with pytest.raises(ValueError, match="must be a mapping"):
        read_config(f)


def test_more_centres_than_vertices_is_refused():
    """Farthest-point sampling cannot place more distinct centres than there are vertices (it
    used to repeat one vertex, and that placement then landed in train, val and test).
    """
    cfg = read_config(_cfg(placements={"disk": {"centres": 16 * 12 + 1, "radii": [0.02]}}))
    with pytest.raises(ValueError, match="193 centres asked for on tube, which has only 192"):
        plan(cfg)
    assert (
        len(
            plan(
                read_config(_cfg(placements={"disk": {"centres": 192, "radii": [0.02]}}))
            ).placements
        )
        == 192
    )


def test_a_set_of_more_places_continues_the_spread_and_may_press_each_on_one_level():
    """``skip``: the centres after the first ones of the same even spread (a second set adds
    places, none repeated); ``thickness_cycle``: each place on one thickness level, in turn.
    """
    first = plan(read_config(_cfg(placements={"disk": {"centres": 4, "radii": [0.02]}})))
    more = plan(
        read_config(
            _cfg(
                thickness_mm=[5.0, 7.5, 10.0],
                thickness_cycle=True,
                placements={"disk": {"centres": 10, "skip": 4, "radii": [0.02]}},
            )
        )
    )
    whole = plan(read_config(_cfg(placements={"disk": {"centres": 10, "radii": [0.02]}})))
    at = [[p["params"]["at"] for p in x.placements] for x in (first, more, whole)]
    assert at[0] + at[1] == at[2] and len(set(at[1])) == 6
    assert more.tasks == [(0, 0), (1, 1), (2, 2), (3, 0), (4, 1), (5, 2)]
    assert len(whole.tasks) == 10  # one level, every place


def test_nothing_to_solve_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match="nothing to solve: even the smallest force"):
        generate(_cfg(max_pressure=1.0), tmp_path / "d", progress=False)
    assert not (tmp_path / "d").exists()


def test_spot_placements():
    """Spots: centres x counts x radii placements, each loading the spots it asks for; a key
    spots do not take, or a count too large for the spread, is named before solving.
    """
    pl = plan(
        read_config(
            _cfg(
                placements={
                    "spots": {"centres": 3, "counts": [1, 3], "radii": [0.01], "spread": 0.05}
                }
            )
        )
    )
    assert [(p["kind"], p["params"]["count"]) for p in pl.placements] == [
        ("spots", 1),
        ("spots", 3),
    ] * 3
    assert all(p["vertices"] >= p["params"]["count"] for p in pl.placements)
    with pytest.raises(ValueError, match=r"placements.spots takes keys \['centres', 'counts'"):
        read_config(_cfg(placements={"spots": {"centres": 3, "angles": [0]}}))
    with pytest.raises(ValueError, match="impossible load placement spots.*widen the spread"):
        plan(
            read_config(_cfg(placements={"spots": {"centres": 1, "counts": [40], "spread": 0.01}}))
        )


def test_grasp_placements(arm):
    """Grasp placements: anny's hand around the arm, each load the vertices it touches (found
    once, before solving); a grasp that touches nothing is left out and counted.
    """
    from fem.placements import make_load

    cfg = read_config(
        {
            "name": "g",
            "body": {"model": "anny"},
            "part": "left_arm",
            "thickness_mm": [7.5],
            "forces": [0.1],
            "placements": {
                "grasp": {
                    "along": [0.7],
                    "around": [0.0],
                    "grips": ["whole"],
                    "hand_heights": [0.5],
                }
            },
        }
    )
    p = plan(cfg, arm)
    assert len(p.placements) == 1 and p.skipped == []
    pl = p.placements[0]
    assert pl["params"] == {
        "along": 0.7,
        "around": 0.0,
        "grip": "whole",
        "hand_height": 0.5,
        "depth": 0.002,
    }
    ld = make_load(arm, pl, total=0.4)
    assert ld.kind == "grasp" and ld.count == len(pl["touched"]) == pl["vertices"] >= 3
    assert ld.force.sum() == pytest.approx(0.4)
    with pytest.raises(ValueError, match="placements.grasp takes keys"):
        read_config({**cfg, "placements": {"grasp": {"hands": [1]}}})


def test_grasps_without_contact_are_counted_not_solved(tmp_path, monkeypatch):
    import fem.placements as P

    def fake(part, params, hands):  # the first grasp misses, the second holds
        if params["along"] < 0.5:
            raise ValueError("no contact: object 'hand' is 2.5 mm from the skin")
        return [10, 11, 12]

    monkeypatch.setattr(P, "grasp_contact", fake)
    cfg = _cfg(placements={"grasp": {"along": [0.3, 0.7]}}, splits=[0.0, 0.0, 1.0])
    card = generate(cfg, tmp_path / "g", progress=False)
    assert card["placements"] == 1 and card["placements_skipped"] == {
        "count": 1,
        "by_reason": {"no contact": 1},
    }
    assert card["samples"] == 2 and card["samples_per_kind"] == {"grasp": 2}


def test_palm_placements(anny_body):
    """Palm placements: anny's open hand laid on a part that is not a limb (the belly), as
    ``stmpl simulate --part belly`` lays it; each load the vertices the palm touches, the same
    ones the simulate scene's contact finds.
    """
    import stmpl.contact.pressing as contact
    from fem.placements import make_load
    from stmpl.contact.hand import Hand, palm_press

    belly = anny_body.part("belly")
    cfg = read_config(
        {
            "name": "p",
            "body": {"model": "anny"},
            "part": "belly",
            "thickness_mm": [7.5],
            "forces": [0.2],
            "placements": {
                "palm": {"uv": [[0.5, 0.5], [0.4, 0.55]], "spins": [0.0, 1.5708], "depth": 0.003}
            },
        }
    )
    p = plan(cfg, belly)
    assert len(p.placements) == 4 and p.skipped == []
    pl = p.placements[0]
    assert pl["params"] == {"uv": [0.5, 0.5], "spin": 0.0, "hand_height": 0.5, "depth": 0.003}
    scene = contact.contact(belly, palm_press(belly, Hand(), (0.5, 0.5), 0.003, np.pi / 2, 0.2))
    assert sorted(pl["touched"]) == sorted(int(v) for v in scene.vertices)
    ld = make_load(belly, pl, total=0.2)
    assert ld.kind == "palm" and ld.count == pl["vertices"] >= 3
    assert ld.force.sum() == pytest.approx(0.2)
    assert len({tuple(q["touched"]) for q in p.placements}) == 4  # four different presses
    with pytest.raises(ValueError, match="placements.palm takes keys"):
        read_config({**cfg, "placements": {"palm": {"centres": 3}}})


def test_a_config_that_leaves_the_forces_out_is_told_the_defaults(tmp_path):
    from fem.config import defaulted

    path = tmp_path / "only.yaml"
    path.write_text("part: left_arm\nplacements: {disk: {centres: 2}}\nthickness_mm: [7.5]\n")
    assert defaulted(path) == ["forces: [0.25, 0.5, 0.75, 1.0]"]
    assert defaulted({"forces": [1.0], "thickness_mm": [5.0]}) == []

"""Checkpoints: written and read back whole; an altered tensor file, an edited sidecar and a
truncated file are each refused, by name.
"""

import json

import pytest
import torch

from stmpl import checkpoint


@pytest.fixture
def saved(tmp_path):
    tensors = {"w": torch.arange(6, dtype=torch.float32).reshape(2, 3)}
    path = checkpoint.write(
        tmp_path / "m.safetensors", tensors, {"kind": "naive", "config": {"disp_scale_mm": 10.0}}
    )
    return path, tensors


def test_round_trip(saved):
    path, tensors = saved
    back, meta = checkpoint.read(path)
    assert torch.equal(back["w"], tensors["w"])
    assert meta["kind"] == "naive" and meta["config"] == {"disp_scale_mm": 10.0}
    assert meta["sha256"] == checkpoint.sha256(path) and meta["bytes"] == path.stat().st_size
    assert meta["digest"] == checkpoint.digest(meta)


def test_every_part_of_the_model_is_covered(saved):
    path, _ = saved
    side = checkpoint.sidecar_path(path)
    original = side.read_text()
    meta = json.loads(original)
    meta["config"]["disp_scale_mm"] = 20.0  # changes every prediction
    side.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="m.json was edited"):
        checkpoint.read(path)
    del meta["digest"]
    side.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="has no digest"):
        checkpoint.read(path)
    side.write_text(original)
    data = bytearray(path.read_bytes())
    data[-1] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="does not match its SHA-256"):
        checkpoint.read(path)
    path.write_bytes(bytes(data[:-4]))
    with pytest.raises(ValueError, match="truncated or altered"):
        checkpoint.read(path)


def test_bad_files_are_named(saved, tmp_path):
    path, tensors = saved
    with pytest.raises(ValueError, match="ends in .safetensors"):
        checkpoint.write(tmp_path / "m.pt", tensors, {"kind": "naive"})
    with pytest.raises(ValueError, match="needs a 'kind'"):
        checkpoint.write(tmp_path / "n.safetensors", tensors, {})
    with pytest.raises(FileNotFoundError, match="checkpoint not found"):
        checkpoint.read(tmp_path / "none.safetensors")
    checkpoint.sidecar_path(path).write_text("[1, 2")
    with pytest.raises(ValueError, match="sidecar .* is corrupt"):
        checkpoint.read(path)
    checkpoint.sidecar_path(path).write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="not a stmpl checkpoint sidecar"):
        checkpoint.read(path)

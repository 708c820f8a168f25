"""The mesh GNN: its feature normalisers travel in the checkpoint."""

import numpy as np

from stmpl import predictor



def test_gnn_normalisers_travel_in_the_checkpoint(ds, tmp_path, make):
    from stmpl import tissue

    p = make("gnn/per_newton", ds)
    q = predictor.read(p.save(tmp_path / "g.safetensors"))
    lo, hi = tissue.THICKNESS_RANGE
    np.testing.assert_allclose(q.model.node_norm.shift.numpy(), [0, 0, lo, 0, 0, 0], atol=1e-9)
    np.testing.assert_allclose(q.model.node_norm.scale.numpy(), [1000, 1, hi - lo, 1, 1, 1],
                               rtol=1e-6)
    edge_len = np.linalg.norm(np.diff(ds.part.vertices[ds.part.edges], axis=1)[:, 0], axis=1)
    np.testing.assert_allclose(q.model.edge_norm.scale.numpy(), edge_len.mean(), rtol=1e-5)

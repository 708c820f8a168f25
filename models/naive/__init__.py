"""The paper's Naive baseline: ``delta = alpha * t_i * F_i`` per axis, ``alpha`` learned."""

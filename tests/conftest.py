"""Shared fixtures: one Anny body per session (its assets build once into $ANNY_CACHE_DIR) and a
fresh stmpl part cache, so part extraction really runs in the tests."""

import os

import numpy as np
import pytest


@pytest.fixture(scope="session", autouse=True)
def _stmpl_cache(tmp_path_factory):
    old = os.environ.get("STMPL_CACHE_DIR")
    os.environ["STMPL_CACHE_DIR"] = str(tmp_path_factory.mktemp("stmpl-cache"))
    yield
    if old is None:
        os.environ.pop("STMPL_CACHE_DIR", None)
    else:
        os.environ["STMPL_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def anny_body():
    from stmpl.body import AnnyBody

    return AnnyBody()


@pytest.fixture(scope="session")
def arm(anny_body):
    return anny_body.part("left_arm")


@pytest.fixture
def rng():
    return np.random.default_rng(0)

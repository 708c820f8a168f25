"""The one-line machine description benchmarks and reports print."""

import os

import torch

from stmpl import machine


def test_the_processor_is_read_from_cpuinfo_else_the_architecture(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nmodel name\t: Test CPU 9000\nflags\t: x\n")
    assert machine.cpu(str(info)) == "Test CPU 9000"
    assert machine.cpu(str(tmp_path / "missing")) == (
        machine.platform.processor() or machine.platform.machine()
    )


def test_the_description_names_the_processor_cores_and_torch():
    assert machine.describe() == (
        f"{machine.cpu()}, {os.cpu_count()} cores, torch "
        f"{torch.__version__} ({torch.get_num_threads()} threads)"
    )

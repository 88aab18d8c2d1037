"""ikseries.memory: the allocator setting the entry points make."""
import platform
import subprocess
import sys

import pytest

from ikseries import memory


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's mallopt")
def test_keep_freed_memory_takes_effect_in_a_fresh_process():
    # in a process of its own: the setting lasts for the process
    out = subprocess.run([sys.executable, "-c", "from ikseries.memory import keep_freed_memory as k; print(k())"],
                         capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True"]


def test_mmap_threshold_within_glibcs_limit():
    assert 0 < memory.MMAP_THRESHOLD <= 32 << 20 < memory.TRIM_THRESHOLD

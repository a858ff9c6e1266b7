"""What users see is what was computed (issue 21 B): conventions, inputs, output folders."""

import os
import stat

import pytest

from modalmorph.io import OUTPUT_MARKER, atomic_output_dir


@pytest.mark.skipif(os.name != "posix", reason="umask is POSIX")
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_output_folders_follow_the_umask(tmp_path, mask):
    old = os.umask(mask)
    try:
        for final in (tmp_path / f"new{mask:o}", tmp_path / f"nested{mask:o}" / "out"):
            for _ in range(2):  # created, then replaced
                with atomic_output_dir(final) as tmp:
                    (tmp / OUTPUT_MARKER).write_text("x")
                assert stat.S_IMODE(final.stat().st_mode) == 0o777 & ~mask
                plain = tmp_path / "plain"  # what mkdir gives, the reference
                plain.mkdir()
                assert stat.S_IMODE(final.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)
                plain.rmdir()
    finally:
        os.umask(old)

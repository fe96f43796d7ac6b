"""`python -m bsp_fast [--version]`: print the package and linked library versions."""
from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bsp_fast",
        description="bsp_fast diagnostics: package version and linked library versions.")
    parser.add_argument("--version", action="store_true",
                        help="print the bsp_fast version and the versions of FFmpeg, OpenCV, "
                             "HDF5, Eigen, assimp and libdeflate it is linked with")
    parser.parse_args(argv)
    import bsp_fast

    for key, value in bsp_fast.diagnostics().items():
        print(f"{key:12s} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

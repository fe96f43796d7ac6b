"""``python -m bsp_fast``: versions, or a subcommand (the console scripts without PATH).

    python -m bsp_fast --version        package and linked library versions
    python -m bsp_fast convert ...      same as bsp-convert
    python -m bsp_fast synth ...        same as bsp-synth
    python -m bsp_fast train ...        same as bsp-train
    python -m bsp_fast eval ...         same as bsp-eval
    python -m bsp_fast predict ...      same as bsp-predict
    python -m bsp_fast reproduce ...    same as bsp-reproduce
    python -m bsp_fast preview ...      same as bsp-preview
    python -m bsp_fast check ...        same as bsp-check
    python -m bsp_fast cache ...        same as bsp-cache
    python -m bsp_fast interop ...      same as bsp-interop
"""
from __future__ import annotations

import sys


def _versions() -> int:
    import bsp_fast

    for key, value in bsp_fast.diagnostics().items():
        print(f"{key:12s} {value}")
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "convert":
        from bsp_fast.conversion import main as convert_main

        return convert_main(argv[1:])
    if argv and argv[0] == "synth":
        from bsp_fast.synth.cli import main as synth_main

        return synth_main(argv[1:])
    training = {"train": "bsp_fast.training.train", "eval": "bsp_fast.training.evaluate",
                "predict": "bsp_fast.training.predict", "reproduce": "bsp_fast.reproduction.cli"}
    if argv and argv[0] in training:
        import importlib

        module = importlib.import_module(training[argv[0]])
        return module.main(argv[1:])
    tools = {"preview": "bsp_fast.preview.cli", "check": "bsp_fast.check.cli",
             "cache": "bsp_fast.data.cache_cli",
             "interop": "bsp_fast.interop.cli"}
    if argv and argv[0] in tools:
        import importlib

        return importlib.import_module(tools[argv[0]]).main(argv[1:])
    if not argv or argv[0] in ("--version", "-V", "version"):
        return _versions()
    print(__doc__.strip(), file=sys.stderr if argv[0] not in ("-h", "--help") else sys.stdout)
    return 0 if argv[0] in ("-h", "--help") else 2


if __name__ == "__main__":
    sys.exit(main())

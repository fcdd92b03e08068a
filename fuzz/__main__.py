"""``python -m fuzz``: one target in this process (``swarm-sitl fuzz`` starts one such process per target).

- ``list``: the targets, one ``name<TAB>about`` line each;
- ``seed [NAME ...]``: write each target's seeds into ``fuzz/corpus/<name>/`` (named by their SHA-1, as libFuzzer
  names what it keeps), leaving what is there;
- ``replay NAME FILE ...``: run files through a target without atheris (a crash raises, with its traceback);
- ``run NAME [libFuzzer flags and corpus directories]``: fuzz it under atheris. The project's modules (and the
  libraries that parse for them: pymavlink, digi-xbee) are instrumented for coverage as they are imported; cantools is
  not (its decoding of a DBC layout has few branches to find, and its encoding in the boards' telemetry, run every
  loop, would halve their targets' speed).
  ``SWARM_SITL_FUZZ_EXE``, when set, is the command libFuzzer re-runs for ``-merge=1`` (its own argv[0] would be this
  file, which is not executable).
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

CORPUS = Path(__file__).resolve().parent / "corpus"
INSTRUMENTED = ["firmware_sim", "swarm_logic", "bridge", "fuzz", "pymavlink", "digi", "msgpack"]


def _seed(names: list[str]) -> int:
    from fuzz import targets

    for name in names or list(targets.MODULE_OF):
        d = CORPUS / name
        d.mkdir(parents=True, exist_ok=True)
        new = 0
        for s in targets.get(name).seeds():
            f = d / hashlib.sha1(s).hexdigest()
            if not f.exists():
                f.write_bytes(s)
                new += 1
        print(f"{name}: {new} new seeds")
    return 0


def _replay(name: str, files: list[str]) -> int:
    from fuzz import targets

    run = targets.get(name).run
    for f in files:
        run(Path(f).read_bytes())
    print(f"{name}: {len(files)} inputs, no crash")
    return 0


def _run(name: str, args: list[str]) -> int:
    import atheris

    from fuzz import targets

    with atheris.instrument_imports(include=INSTRUMENTED):
        target = targets.get(name)
    argv0 = os.environ.get("SWARM_SITL_FUZZ_EXE") or sys.argv[0]
    atheris.Setup([argv0, *args], target.run)
    atheris.Fuzz()
    return 0


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("list", "seed", "replay", "run"):
        print(__doc__, file=sys.stderr)
        return 2
    cmd, rest = argv[0], argv[1:]
    if cmd == "list":
        from fuzz.targets import all_targets

        for name, t in all_targets().items():
            print(f"{name}\t{t.about}")
        return 0
    if cmd == "seed":
        return _seed(rest)
    if cmd == "replay":
        return _replay(rest[0], rest[1:])
    return _run(rest[0], rest[1:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

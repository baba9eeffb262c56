"""Run mutmut with numba's ``@njit`` allowed as a decorator (``python run_mutmut.py run ...``).

mutmut 3 does not mutate decorated functions (it keeps the decorators on its trampoline and
on every mutated copy, and a decorator such as ``@app.post("/x")`` may act when it runs
more than once). Every function of :mod:`observer.kernel` is decorated ``@njit(**JIT)``
(sometimes with ``inline="always"``), so none would be mutated. Under
``NUMBA_DISABLE_JIT=1`` numba's ``njit(...)`` returns the plain Python function, so the
trampoline, the original copy and the mutated copies all stay plain functions and the
decorator is harmless. This wrapper (the approach of boxed/mutmut#387) replaces mutmut's
"skip decorated functions" rule by one that lets through a function whose decorators are
all in :data:`ALLOWED_DECORATORS` — ``njit`` or ``njit(...)``, nothing else — and applies
every other skip rule of mutmut unchanged (pragmas, never-mutated names, defaults,
annotations; the decorator's own arguments are still never mutated). It sets
``NUMBA_DISABLE_JIT=1`` before mutmut (and so numba) is imported: a trampoline cannot be
compiled. mutmut forks its workers, so the patch reaches them.

``python run_mutmut.py run --sample N --seed S`` runs a uniform random sample instead of every
mutant: it generates the mutants (mutmut's own generation), draws ``N`` of all their names
without replacement with ``random.Random(S)`` (names sorted first, so the draw depends only
on the source and the seed), writes the draw to ``mutants/sample.json`` and runs mutmut on
exactly those names (``mutmut run NAME ...``: stats, clean run and forced-fail run as usual,
then each named mutant against the tests that reach its function). A complete run of the
plain-Python targets needs hours; a sample of 60–100 gives the score with a binomial
confidence interval (``noxfile._mutation_summary``).
"""

from __future__ import annotations

import json
import os
import random
import sys
from pathlib import Path

os.environ["NUMBA_DISABLE_JIT"] = "1"

import libcst as cst  # noqa: E402
from libcst.metadata import PositionProvider  # noqa: E402
from mutmut.mutation import file_mutation  # noqa: E402

ALLOWED_DECORATORS = frozenset({"njit"})


def _allowed(decorator: cst.Decorator) -> bool:
    d = decorator.decorator
    if isinstance(d, cst.Call):
        d = d.func
    return isinstance(d, cst.Name) and d.value in ALLOWED_DECORATORS


_original_skip = file_mutation.MutationVisitor._skip_node_and_children


def _skip_node_and_children(self, node: cst.CSTNode) -> bool:
    if isinstance(node, cst.FunctionDef) and node.decorators and all(map(_allowed, node.decorators)):
        # the position rules need the node itself (metadata is keyed by node): a pragma
        # "no mutate" on the def line still skips it
        position = self.get_metadata(PositionProvider, node, None)
        if position and position.start.line in self._ignored_node_lines:
            return _original_skip(self, node)
        # every other rule, judged on the function without its (allowed) decorators
        return _original_skip(self, node.with_changes(decorators=[]))
    return _original_skip(self, node)


file_mutation.MutationVisitor._skip_node_and_children = _skip_node_and_children

SAMPLE_FILE = Path("mutants") / "sample.json"


def _take_option(argv: list[str], name: str) -> str | None:
    """Remove ``name VALUE`` from ``argv`` and return VALUE (None if absent)."""
    if name not in argv:
        return None
    i = argv.index(name)
    value = argv[i + 1]
    del argv[i:i + 2]
    return value


def draw_sample(names: list[str], size: int, seed: int) -> list[str]:
    """A uniform sample of ``size`` mutant names without replacement (all if fewer), drawn
    from the sorted names with ``random.Random(seed)``: reproducible from source and seed."""
    population = sorted(names)
    return sorted(random.Random(seed).sample(population, min(size, len(population))))


def generate_and_sample(size: int, seed: int, max_children: int) -> list[str]:
    """Generate every mutant of the configured files (mutmut's generation step), draw the
    sample, write it to :data:`SAMPLE_FILE` and return its names."""
    from mutmut import __main__ as mm

    mm.set_mutant_under_test("mutant_generation")
    os.makedirs("mutants", exist_ok=True)
    mm.copy_src_dir()
    mm.copy_also_copy_files()
    mm.setup_source_paths()
    mm.store_lines_covered_by_tests()
    mm.create_mutants(max_children)
    mutants, _ = mm.collect_source_file_mutation_data(mutant_names=[])
    names = [name for _, name, _ in mutants]
    sample = draw_sample(names, size, seed)
    SAMPLE_FILE.write_text(json.dumps(dict(seed=seed, size=len(sample), population=len(names),
                                           names=sample), indent=1), encoding="utf-8")
    print(f"sampled {len(sample)} of {len(names)} mutants (seed {seed}) -> {SAMPLE_FILE}")
    return sample


def main(argv: list[str]) -> int:
    """mutmut's command line, with ``run --sample N --seed S`` for a sampled run."""
    from mutmut.__main__ import cli

    size, seed = _take_option(argv, "--sample"), _take_option(argv, "--seed")
    if size is not None:
        if argv[:1] != ["run"] or argv[1:2] and not argv[1].startswith("--"):
            raise SystemExit("--sample goes with 'run' and no mutant names")
        children = _take_option(argv, "--max-children")
        max_children = int(children) if children else (os.cpu_count() or 4)
        names = generate_and_sample(int(size), int(seed or 0), max_children)
        argv = ["run", "--max-children", str(max_children), *names]
    return cli(argv, prog_name="mutmut")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

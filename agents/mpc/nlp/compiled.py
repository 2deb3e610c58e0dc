"""Compiled solvers: the NLP's functions generated as C by :class:`casadi.CodeGenerator`, compiled
by ``$CC`` (gcc) into a shared library in a private temporary directory and kept in a disk cache
under a hash of the NLP, so later processes load it (see "Compiled solvers" in
:mod:`agents.mpc.nlp.solver`)."""

from __future__ import annotations

import atexit
import functools
import hashlib
import os
import shlex
import shutil
import subprocess
import tempfile
import warnings
from typing import Any

import casadi as ca

DEFAULT_JIT_CACHE = os.environ.get(
    "RISKMPC_JIT_CACHE", os.path.join(os.path.expanduser("~"), ".cache", "riskcrossing", "jit")
)
"""Where compiled solvers (shared libraries) are kept between processes."""
_COMPILED_FUNCTIONS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l", "nlp_grad")
"""The nlpsol functions a compiled solver takes from its shared library (the rest are derived)."""


def have_c_compiler() -> bool:
    """Whether the C compiler for compiled solvers (``$CC``, e.g. ``"ccache gcc"``, or ``gcc``) can
    be found."""
    command = shlex.split(os.environ.get("CC", "gcc"))
    return bool(command) and shutil.which(command[0]) is not None


def compiled_library(
    nlp: dict[str, Any],
    options: dict[str, Any],
    solver_name: str,
    jit_opt: int,
    jit_cache: str | os.PathLike[str] | None,
) -> str | None:
    """The path of a shared library with the functions of ``nlp`` (the NLP and the derivatives the
    solver evaluates), from the disk cache when it holds this exact NLP, else compiled.

    The library is generated with :class:`casadi.CodeGenerator` and compiled by ``$CC`` (or gcc) at
    ``-O{jit_opt}`` in a private temporary directory, then moved into ``jit_cache`` under a hash of
    the NLP, the CasADi version and the compiler flags, so any later process (or agent) with the same
    NLP loads it in milliseconds. Nothing is written to the working directory and the process never
    changes directory. (CasADi's own ``jit`` option cannot promise that: in CasADi 3.8 nlpsol's jit
    writes its C source to the working directory whatever ``jit_options["directory"]`` says.)
    ``solver_name`` is the nlpsol plugin (``"fatrop"`` or ``"ipopt"``), ``options`` its options;
    ``jit_cache=None`` keeps the library in a per-process temporary directory.
    Returns None (with a warning) when code generation, compilation or loading fails.
    ``ca.nlpsol(name, solver, library, options)`` then builds a solver on it.
    """
    oracle = ca.Function("nlp", [nlp["x"], nlp["p"]], [nlp["f"], nlp["g"]], ["x", "p"], ["f", "g"])
    solver = ca.nlpsol("mpc", solver_name, oracle, options)  # for its derivative functions
    names = [n for n in _COMPILED_FUNCTIONS if solver.has_function(n)]
    compiler = os.environ.get("CC", "gcc")
    flags = [f"-O{jit_opt}"]
    key = [ca.__version__, compiler, " ".join(flags), " ".join(names), oracle.serialize()]
    digest = hashlib.sha256("\n".join(key).encode()).hexdigest()[:24]
    name = f"riskmpc_{digest}"
    cache = _private_cache() if jit_cache is None else os.fspath(jit_cache)
    library = os.path.join(cache, f"{name}.so")
    try:
        if not os.path.exists(library):
            os.makedirs(cache, exist_ok=True)
            with tempfile.TemporaryDirectory(prefix="riskmpc_build_") as tmp:
                generator = ca.CodeGenerator(name, {"with_header": False})
                generator.add(oracle)
                for n in names:
                    generator.add(solver.get_function(n))
                source = generator.generate(tmp + os.sep)
                built = os.path.join(tmp, f"{name}.so")
                subprocess.run(
                    [*shlex.split(compiler), "-fPIC", "-shared", *flags, source, "-o", built],
                    cwd=tmp,
                    check=True,
                    capture_output=True,
                )
                partial = f"{library}.{os.getpid()}.tmp"
                shutil.move(built, partial)
                os.replace(partial, library)  # atomic: no process loads a half-written library
        ca.nlpsol("mpc", solver_name, library, options)  # loads: raises here, not in the caller
        return library
    except Exception as err:  # a broken compiler must not break the agent
        detail = (getattr(err, "stderr", None) or b"").decode(errors="replace")[:300]
        warnings.warn(f"compiling the solver failed ({err} {detail}); building without jit", stacklevel=6)
        return None


@functools.cache
def _private_cache() -> str:
    """A per-process directory for compiled solvers when ``jit_cache=None`` (removed at exit)."""
    path = tempfile.mkdtemp(prefix="riskmpc_jit_")
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path

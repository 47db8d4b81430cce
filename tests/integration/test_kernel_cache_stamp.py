"""A cached kernel is recompiled when a kernel it calls changes in another module
(tolsim._jit.KernelTreeStamp).

Numba stamps a cached kernel with its own file's hash only, although the machine code it
saves holds its callees' code: after an edit of a callee's module (a git checkout in a working
tree, an editable install) the caller's stale code was loaded and gave the old numbers.
Checked in fresh processes on a package of two kernel modules below the stamp's root, with
Numba's own locator as the negative control (which must show the stale number).
"""

import os
import subprocess
import sys
import textwrap

import pytest

CALLEE = "from tolsim._jit import jit\n\n\n@jit\ndef value():\n    return {}\n"
CALLER = textwrap.dedent("""\
    from tolsim._jit import jit
    from pkg.callee import value


    @jit
    def twice():
        return 2 * value()
    """)
RUN = textwrap.dedent("""\
    import sys
    from tolsim import _jit
    _jit.KernelTreeStamp.root = sys.argv[1]
    if sys.argv[2] == "numba":  # Numba's own locators: the tolsim ones set aside
        from numba.core import caching
        impl = getattr(caching, "CacheImpl", getattr(caching, "_CacheImpl", None))
        classes = impl._locator_classes
        classes[:] = [c for c in classes if not issubclass(c, _jit.KernelTreeStamp)]
    sys.path.insert(0, sys.argv[1])
    from pkg.caller import twice
    print(twice())
    """)


def run(root, tmp_path, locators):
    out = subprocess.run([sys.executable, "-c", RUN, str(root), locators], check=True,
                         capture_output=True, text=True, cwd=tmp_path,
                         env=dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache")))
    return int(out.stdout.strip())


@pytest.mark.parametrize("locators, after_edit", [("tolsim", 6), ("numba", 4)])
def test_a_changed_callee_recompiles_its_callers(tmp_path, locators, after_edit):
    root = tmp_path / "src"
    (root / "pkg").mkdir(parents=True)
    (root / "pkg" / "__init__.py").write_text("")
    (root / "pkg" / "callee.py").write_text(CALLEE.format(2))
    (root / "pkg" / "caller.py").write_text(CALLER)
    assert run(root, tmp_path, locators) == 4  # compiled and cached
    assert run(root, tmp_path, locators) == 4  # loaded from the cache
    (root / "pkg" / "callee.py").write_text(CALLEE.format(3))
    # the caller's file is unchanged; tolsim's stamp sees the callee's change, Numba's does not
    assert run(root, tmp_path, locators) == after_edit


def test_the_stamp_is_installed_for_the_package():
    # Numba's locator list is private: if a release moves it, the stamp is not installed
    # and this fails (the package then runs with Numba's own stamps).
    from numba.core import caching

    from tolsim import _jit

    impl = getattr(caching, "CacheImpl", getattr(caching, "_CacheImpl", None))
    assert any(issubclass(c, _jit.KernelTreeStamp) for c in impl._locator_classes)
    assert _jit.kernel_sources_digest(_jit.KernelTreeStamp.root)  # the package's kernels

"""mjx_hands sets its CPU code-generation flag only where XLA will read it safely."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from mjx_hands import xla_flags

PROBE = """
import json, os, sys, warnings
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    if sys.argv[1] == "jax-first":
        import jax.numpy as jnp
        jnp.ones(1).block_until_ready()  # starts the CPU backend
    import mjx_hands
    import jax
    jax.numpy.ones(1).block_until_ready()  # XLA parses XLA_FLAGS (aborts on unknown flags)
messages = [str(w.message) for w in caught]
print(json.dumps({"flags": os.environ.get("XLA_FLAGS"), "warnings": messages}))
"""


def _probe(mode: str, xla_flags_env: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if xla_flags_env is not None:
        env["XLA_FLAGS"] = xla_flags_env
    out = subprocess.run(
        [sys.executable, "-c", PROBE, mode],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.splitlines()[-1])


def test_import_adds_the_flag_and_keeps_the_users_flags():
    if not xla_flags._jaxlib_knows(xla_flags.FLAG_NAME):
        assert _probe("plain", None)["flags"] is None  # an unknown flag would abort XLA
        return
    assert _probe("plain", None)["flags"] == xla_flags.FLAG
    got = _probe("plain", "--xla_force_host_platform_device_count=2")["flags"]
    assert got.split() == ["--xla_force_host_platform_device_count=2", xla_flags.FLAG]


def test_an_explicit_user_choice_wins():
    mine = "--xla_cpu_use_fusion_emitters=true"
    got = _probe("plain", mine)
    assert got["flags"] == mine and not got["warnings"]


def test_jax_started_first_leaves_flags_alone_and_says_why():
    got = _probe("jax-first", None)
    assert got["flags"] is None
    if xla_flags._jaxlib_knows(xla_flags.FLAG_NAME):
        assert any("JAX started before mjx_hands" in w for w in got["warnings"])


def test_the_binary_probe_tells_known_from_unknown_flags():
    assert not xla_flags._jaxlib_knows("xla_cpu_no_such_flag_" + "0123456789abcdef")


def test_only_a_registered_flag_counts_not_a_leftover_proto_field(tmp_path, monkeypatch):
    """A flag XLA removed can keep its DebugOptions proto field (a length-prefixed name);
    setting it would abort XLA, so only the parser's C-string name counts."""
    import types

    fake = types.ModuleType("jaxlib")
    fake.__file__ = str(tmp_path / "__init__.py")
    monkeypatch.setitem(sys.modules, "jaxlib", fake)
    name = b"xla_cpu_made_up_flag"
    (tmp_path / "libproto.so").write_bytes(b"\x12\x14\n" + bytes([len(name)]) + name + b"\x18")
    assert not xla_flags._jaxlib_knows(name.decode())
    (tmp_path / "libflags.so").write_bytes(b"Dump IR.\x00" + name + b"\x00Other help.")
    assert xla_flags._jaxlib_knows(name.decode())


CACHE_PROBE = """
import jax
from mjx_hands import compile_cache
print(compile_cache.enable(), jax.config.jax_compilation_cache_dir)
jax.jit(lambda x: x * 2.0)(1.0).block_until_ready()  # compiled with the cache in use
"""


def test_commands_cache_compiled_programs_in_a_folder_the_user_can_override(tmp_path):
    """The commands put JAX's persistent cache in the user's cache folder, unless the
    user named another one or turned caching off."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
    env |= {"XDG_CACHE_HOME": str(tmp_path), "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0"}
    mine = tmp_path / "mine"
    cases = [
        ({}, str(tmp_path / "mjx_hands" / "jax")),
        ({"JAX_COMPILATION_CACHE_DIR": str(mine)}, str(mine)),
        ({"JAX_ENABLE_COMPILATION_CACHE": "false"}, None),
    ]
    for extra, folder in cases:
        out = subprocess.run(
            [sys.executable, "-c", CACHE_PROBE], env=env | extra, capture_output=True, text=True,
            timeout=120, check=False,
        )  # fmt: skip
        assert out.returncode == 0, out.stderr
        used, configured = out.stdout.split()[-2:]
        assert used == str(folder)
        if folder is not None:
            assert configured == folder and any(Path(folder).iterdir())  # written there

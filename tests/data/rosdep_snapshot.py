"""Write ``rosdep_keys.json``: the rosdep keys of a rosdistro checkout and how each resolves on
Ubuntu 24.04 (noble), the platform of ROS 2 Jazzy (REP 2000), for ``tests/test_rosdep.py``.

    python tests/data/rosdep_snapshot.py ROSDISTRO_GIT_DIR [COMMIT]

reads ``rosdep/base.yaml``, ``rosdep/python.yaml`` and ``jazzy/distribution.yaml`` at COMMIT
(default HEAD) of a clone of https://github.com/ros/rosdistro with ``git show``; the file records
that commit. A key's rule for ``ubuntu`` is a package list (apt), an installer mapping
(``pip: {packages: [...]}``) or a mapping of release codenames (``noble``, ``'*'``) to either;
``null`` or a missing ``ubuntu`` entry means the key does not resolve there (rosdep has no
fallback from one OS to another). Every package released into Jazzy resolves to its
``ros-jazzy-*`` Debian package.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml

CODENAME = "noble"
INSTALLERS = ("apt", "pip", "source")


def _installer(rule: Any) -> str | None:
    """How one OS rule installs on noble: ``apt``, ``pip``, ``source`` or None (unavailable)."""
    if rule is None:
        return None
    if isinstance(rule, list):
        return "apt"
    if isinstance(rule, dict):
        for installer in INSTALLERS:
            if installer in rule:
                return installer
        return _installer(rule.get(CODENAME, rule.get("*")))
    return None


def noble_rules(database: dict[str, Any]) -> dict[str, str | None]:
    """Each key of a rosdep database and its installer on Ubuntu noble (None: unavailable)."""
    return {key: _installer(rules.get("ubuntu")) if isinstance(rules, dict) else None for key, rules in database.items()}


def jazzy_packages(distribution: dict[str, Any]) -> list[str]:
    """The packages released into ROS 2 Jazzy (a repository's release lists them; none: its name)."""
    out: set[str] = set()
    for name, repo in distribution["repositories"].items():
        release = repo.get("release")
        if release:
            out.update(release.get("packages", [name]))
    return sorted(out)


def main(git_dir: str, commit: str = "HEAD") -> None:
    def show(path: str) -> Any:
        return yaml.safe_load(subprocess.run(["git", "--git-dir", git_dir, "show", f"{commit}:{path}"],
                                             capture_output=True, check=True, text=True).stdout)

    sha = subprocess.run(["git", "--git-dir", git_dir, "rev-parse", commit], capture_output=True, check=True,
                         text=True).stdout.strip()
    rules = {**noble_rules(show("rosdep/base.yaml")), **noble_rules(show("rosdep/python.yaml"))}
    snapshot = {
        "source": "https://github.com/ros/rosdistro",
        "commit": sha,
        "platform": f"ubuntu {CODENAME}",
        "files": ["rosdep/base.yaml", "rosdep/python.yaml", "jazzy/distribution.yaml"],
        "rosdep_keys": dict(sorted(rules.items())),
        "jazzy_packages": jazzy_packages(show("jazzy/distribution.yaml")),
    }
    out = Path(__file__).with_name("rosdep_keys.json")
    out.write_text(json.dumps(snapshot, indent=0, sort_keys=False) + "\n")
    print(f"wrote {out}: {len(rules)} rosdep keys, {len(snapshot['jazzy_packages'])} Jazzy packages at {sha}")


if __name__ == "__main__":
    main(*sys.argv[1:])

"""Options tried, measured and not adopted, then removed from the config: :data:`RETIRED`.

Old run folders load as they did (:mod:`.loading`, ``train/folder.py``): a saved config that holds a
retired option at the value that left it off loads without it (:func:`without_retired`); one that had
it on is refused, naming the last commit with the option's code, which that run needs. Retiring an
option is a line here; docs/training.md, "The measurements", links each one's measurement. Imports no
config: what it reads and returns is the plain mapping a run saved.
"""

from __future__ import annotations

from typing import Any, Dict, Tuple

from ..settings_checks import ConfigError

__all__ = ["RETIRED", "without_retired"]

#: Options tried, measured and not adopted, then removed from the config (issues 43, 44): ``(section,
#: key)`` → their value when off, and the last commit with their code (docs/training.md, "The measurements").
RETIRED: Dict[Tuple[str, str], Tuple[Any, str]] = {
    ("model", "texture_surface"): (False, "3afe14f"),
    ("model", "texture_sides"): (False, "3afe14f"),
    ("model", "texture_blur"): (0.0, "3afe14f"),
    ("train", "adv_input"): (0.0, "3afe14f"),
    ("train", "light_warmup"): (0, "3afe14f"),
    ("train", "light_fade"): (0, "3afe14f"),
    ("train", "r1_every"): (1, "3afe14f"),
    ("train", "silhouette_weight"): (0.0, "60a45a0"),      # issue 43
    ("train", "symmetry"): (0.0, "3bef62f"),               # issue 43
    ("train", "turn_about"): ("volume", "55e7013"),        # issue 43
    ("model", "texture_rim"): (90.0, "f98b5e7"),           # issue 43
}


def without_retired(saved: Dict[str, Any]) -> Dict[str, Any]:
    """A saved config (the mapping a run wrote) without the :data:`RETIRED` keys it holds at their off
    value; :class:`ConfigError` naming the key and the commit to check out if one was on."""
    out = {name: dict(section) if isinstance(section, dict) else section for name, section in saved.items()}
    for (section, key), (off, commit) in RETIRED.items():
        values = out.get(section)
        if isinstance(values, dict) and key in values:
            value = values.pop(key)
            if value != off:
                raise ConfigError(f"{section}.{key}: {value!r} was tried and retired "
                                  f"(docs/training.md, 'The measurements'); "
                                  f"this run needs the code of commit {commit}")
    return out

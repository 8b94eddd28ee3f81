"""The field check of the config readers (model, rate, reversal): one function with no imports
from the rest of the package, so that every reader can use it."""
from __future__ import annotations


def check_fields(what: str, d: dict, required, optional=()) -> None:
    """ValueError naming every missing key of ``required`` and every key of ``d`` in neither
    ``required`` nor ``optional`` (a hand-edited config must not fall back to a default behind the
    user's back, nor have a misspelled key ignored)."""
    missing = [k for k in required if k not in d]
    unknown = sorted(set(d) - set(required) - set(optional))
    if missing or unknown:
        raise ValueError(f"{what}: " + "; ".join(([f"missing {', '.join(missing)}"] if missing else [])
                                                + ([f"unknown {', '.join(unknown)}"] if unknown else []))
                         + f" (fields: {', '.join(list(required) + list(optional))})")

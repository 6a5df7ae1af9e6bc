"""Hypothesis strategies shared by the fuzz tests of the user-input parsers."""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

# What YAML can hold: scalars (NaN, inf and huge numbers included), lists and mappings.
SCALARS = (
    st.none() | st.booleans() | st.integers(min_value=-(2**70), max_value=2**70) | st.floats() | st.text(max_size=6)
)
YAML_VALUES = st.recursive(
    SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)


@st.composite
def mutated(draw: Any, document: Any) -> Any:
    """``document`` with one value somewhere in it replaced by junk (or a key dropped):
    close enough to a valid file to reach the parser's inner checks."""
    if not isinstance(document, (dict, list)) or not document or draw(st.integers(0, 4)) == 0:
        return draw(YAML_VALUES)
    if isinstance(document, dict):
        key = draw(st.sampled_from(sorted(document, key=str)))
        copy = dict(document)
        if draw(st.booleans()) and draw(st.integers(0, 3)) == 0:
            del copy[key]
        else:
            copy[key] = draw(mutated(document[key]))
        return copy
    index = draw(st.integers(0, len(document) - 1))
    items = list(document)
    items[index] = draw(mutated(document[index]))
    return items

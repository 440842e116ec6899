"""The MERL material-type vocabulary and the text descriptions of conditional synthesis.

Zhou et al. (NeuMaDiff, supplementary C.2) condition on 48 material types derived from the
names of the 100 MERL materials; Hu (TR-1005, § 3.5.1) describes the derivation: colour and
other unrelated words are dropped from the name. The rule here, applied to a material name:

1. lower case; a trailing number, with or without its hyphen, is dropped
   (`blue-metallic-paint2`, `cherry-235`, `color-changing-paint1`);
2. colour and tone words are dropped wherever they stand (`specular-black-phenolic` →
   `specular-phenolic`, `two-layer-gold` → `two-layer`, `light-brown-fabric` → `fabric`);
3. five leftovers name their type another way: `cherry` → `wood`, `ss` (MERL's `ss440`,
   AISI 440 stainless steel) → `stainless-steel`, `diffuse-bball` → `diffuse-ball`,
   `matte-plastic` → `plastic`, `pure-rubber` → `rubber`.

What remains is the type where it is one of the 48, else the material has none (a
material from outside MERL, or a name the rule does not know). The 100 MERL names give
exactly the 48 types (tests/unit/test_material_types.py).

A material has one type, a PCA interpolation of two the types of both (Hu concatenates
their two embeddings, a pure material's twice). Descriptions follow Zhou et al. § 4.4: a material's name as a phrase (`blue metallic
paint`); a colour-permuted copy keeps it without its colour words (`metallic paint`); a
PCA interpolation of A and B is "a mixture of A and B".
"""

from __future__ import annotations

import difflib
import re

from ..errors import ConfigError

#: Zhou et al., supplementary C.2, in their order; a type's index is its integer label.
MERL_TYPES: tuple[str, ...] = (
    "acrylic", "alum-bronze", "alumina-oxide", "aluminium", "aventurnine", "brass", "wood", "chrome-steel",
    "chrome", "colonial-maple", "color-changing-paint", "delrin", "diffuse-ball", "fabric", "felt", "fruitwood",
    "grease-covered-steel", "hematite", "ipswich-pine", "jasper", "latex", "marble", "metallic-paint", "natural",
    "neoprene-rubber", "nickel", "nylon", "obsidian", "oxidized-steel", "paint", "phenolic", "pickled-oak",
    "plastic", "polyethylene", "polyurethane-foam", "pvc", "rubber", "silicon-nitrade", "soft-plastic",
    "special-walnut", "specular-fabric", "specular-phenolic", "specular-plastic", "stainless-steel", "steel",
    "teflon", "tungsten-carbide", "two-layer",
)

#: Words that say a material's colour or tone, not its type.
COLOUR_WORDS = frozenset({
    "beige", "black", "blue", "brown", "dark", "gold", "gray", "green", "grey", "light", "maroon", "orange",
    "pearl", "pink", "purple", "red", "silver", "violet", "white", "yellow",
})

#: What the rule leaves of five MERL names, and the type each names.
ALIASES = {"cherry": "wood", "ss": "stainless-steel", "diffuse-bball": "diffuse-ball",
           "matte-plastic": "plastic", "pure-rubber": "rubber"}

#: Words of MERL names that read as other words in a description.
PHRASES = {"ss": "stainless steel", "bball": "ball"}

_TRAILING_NUMBER = re.compile(r"-?\d+$")


def _words(name: str) -> list[str]:
    return [w for w in re.split(r"[-_\s]+", _TRAILING_NUMBER.sub("", name.strip().lower())) if w]


def material_type(name: str) -> str | None:
    """The MERL type of a material name (see the module docstring), or None."""
    stem = "-".join(w for w in _words(name) if w not in COLOUR_WORDS)
    stem = ALIASES.get(stem, stem)
    return stem if stem in MERL_TYPES else None


def type_index(type_name: str) -> int:
    """A type's integer label (its place in MERL_TYPES); a name outside the vocabulary is a
    ConfigError with the nearest types."""
    return MERL_TYPES.index(checked_type(type_name))


def checked_type(type_name: str, key: str = "type") -> str:
    """`type_name` if it is one of the 48, else a ConfigError naming `key` and the nearest types."""
    if type_name in MERL_TYPES:
        return type_name
    near = difflib.get_close_matches(str(type_name), MERL_TYPES, n=3)
    hint = f"; did you mean {' or '.join(repr(n) for n in near)}?" if near else ""
    raise ConfigError(f"{key}={type_name!r} is not a MERL material type{hint} (the 48 types of Zhou et al., C.2)")


def describe(name: str) -> str:
    """A material's name as a phrase: `blue-metallic-paint2` → "blue metallic paint",
    `ss440` → "stainless steel"."""
    return " ".join(PHRASES.get(w, w) for w in _words(name)) or name


def without_colour(description: str) -> str:
    """A description with its colour words dropped ("red metallic paint" → "metallic paint")."""
    kept = [w for w in description.split() if w.lower() not in COLOUR_WORDS]
    return " ".join(kept) or description


def mixture(a: str, b: str) -> str:
    """The description of a PCA interpolation of materials described as `a` and `b`."""
    return f"a mixture of {a} and {b}"

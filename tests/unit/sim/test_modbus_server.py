"""The Modbus simulator's register encoding against hand-worked words (Modbus stores 16-bit
big-endian registers; 32-bit values take two, the word order as configured; f32 is IEEE 754).
The simulator serving the real driver over TCP: tests/system/drivers/test_modbus.py."""

from __future__ import annotations

import pytest

from gonio.config import Register
from gonio.sim.modbus_server import from_words, to_words


def reg(type_: str, scale: float = 1.0, word_order: str = "big") -> Register:
    return Register.model_validate({"address": 0, "type": type_, "scale": scale,
                                    "word_order": word_order})


@pytest.mark.parametrize(("type_", "scale", "order", "physical", "words"), [
    ("u16", 1.0, "big", 1234, [1234]),
    ("u16", 0.001, "big", 0.5, [500]),  # raw = physical / scale
    ("s16", 1.0, "big", -2, [0xFFFE]),  # two's complement
    ("u32", 1.0, "big", 0x12345678, [0x1234, 0x5678]),
    ("u32", 1.0, "little", 0x12345678, [0x5678, 0x1234]),
    ("s32", 1.0, "big", -1, [0xFFFF, 0xFFFF]),
    ("f32", 1.0, "big", 1.0, [0x3F80, 0x0000]),  # IEEE 754 single: 0x3F800000
    ("f32", 1.0, "little", -2.0, [0x0000, 0xC000]),  # 0xC0000000, low word first
])
def test_values_become_the_words_a_device_stores(type_: str, scale: float, order: str,
                                                 physical: float, words: list[int]) -> None:
    r = reg(type_, scale, order)
    assert to_words(r, physical) == words
    assert from_words(r, words) == pytest.approx(physical)


@pytest.mark.parametrize(("type_", "physical", "words"), [
    ("u16", 70000, [0xFFFF]), ("u16", -5, [0]), ("s16", -40000, [0x8000]),
    ("s16", 40000, [0x7FFF]), ("u32", 2.0**40, [0xFFFF, 0xFFFF]),
])
def test_a_value_out_of_range_saturates_like_an_adc(type_: str, physical: float,
                                                    words: list[int]) -> None:
    assert to_words(reg(type_), physical) == words


def test_a_value_is_rounded_to_the_nearest_raw_count() -> None:
    assert to_words(reg("u16", 0.01), 1.234) == [123]
    assert to_words(reg("u16", 0.01), 1.236) == [124]

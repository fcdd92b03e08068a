"""Emulated robot firmware: boards, their peripherals, and the sketches that run on them."""

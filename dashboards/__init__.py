"""The operators' dashboard (piStatus-style fleet health) and analysts' pages."""

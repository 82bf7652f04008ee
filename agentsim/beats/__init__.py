"""Beats from audio: a causal beat tracker (an onset-envelope front end, tempo, phase and a Kalman
follower), baselines, and their evaluation against reference beats."""

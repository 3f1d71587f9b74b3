"""Tracking filters: the Kalman family, grid Bayes and particle filters."""

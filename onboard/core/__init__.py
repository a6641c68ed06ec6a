"""The core every other part of onboard builds on: typed samples and estimate records
(messages), the configuration and its errors, angles and the local frame (geo),
rotations (so3) and the chi-square distribution of the gates and bands (stats). It imports
nothing else of this project."""

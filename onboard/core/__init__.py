"""The core every other part of onboard builds on: typed samples and estimate records
(messages), the configuration and its errors, angles and the local frame (geo), and
rotations (so3). It imports nothing else of this project."""

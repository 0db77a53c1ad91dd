//! Guided camera calibration with Max ERE (seed 004_815695db12a6b16c.txt ch. 5).

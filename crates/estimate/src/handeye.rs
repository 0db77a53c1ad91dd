//! Hand-eye auto-teaching: the UKF model and the SLAM-MOT factor graph (seed 000_3b1454b2b2194811.txt ch. 5).

//! Collision checking of the robot links against the workspace with parry (seed 000_3b1454b2b2194811.txt eq. 6.20).

//! Multi-wafer tracking (seed 000_3b1454b2b2194811.txt ch. 4, Algorithms 4 and 5).

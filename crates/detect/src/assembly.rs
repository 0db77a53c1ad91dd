//! Elliptic-segment assembly: the two-arc combination rule, Algorithms 1 and 2 (seed 000_3b1454b2b2194811.txt ch. 3.2).

//! Global voting of rigid transforms between point sets (seed 000_3b1454b2b2194811.txt eq. 3.19–3.22, Algorithm 3).

// Kirsch's plate: a square plate of side 40 with a circular hole of radius a = 1 at its centre.
a = 1; L = 20; h_hole = 0.1; h_out = 2;
Point(1) = {-L, -L, 0, h_out}; Point(2) = {L, -L, 0, h_out}; Point(3) = {L, L, 0, h_out}; Point(4) = {-L, L, 0, h_out};
Point(5) = {0, 0, 0, h_hole};
Point(6) = {a, 0, 0, h_hole}; Point(7) = {0, a, 0, h_hole}; Point(8) = {-a, 0, 0, h_hole}; Point(9) = {0, -a, 0, h_hole};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Circle(5) = {6, 5, 7}; Circle(6) = {7, 5, 8}; Circle(7) = {8, 5, 9}; Circle(8) = {9, 5, 6};
Curve Loop(1) = {1, 2, 3, 4}; Curve Loop(2) = {5, 6, 7, 8};
Plane Surface(1) = {1, 2};
Physical Surface("plate") = {1};
Physical Curve("hole") = {5, 6, 7, 8};
Physical Curve("left") = {4};
Physical Curve("right") = {2};

h = 0.2;
Point(1) = {0, 0, 0, h}; Point(2) = {1, 0, 0, h}; Point(3) = {1, 1, 0, h}; Point(4) = {0, 1, 0, h};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4}; Plane Surface(1) = {1};
Point(5) = {0.3, 0.5, 0, h}; Point(6) = {0.7, 0.5, 0, h}; Line(5) = {5, 6};
Line{5} In Surface{1}; Recombine Surface{1};
Physical Surface("body") = {1};
Physical Curve("base") = {1};
Physical Curve("crack") = {5};

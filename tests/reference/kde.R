# Reference values for src/stats/kde.rs from R's own bw.nrd0 and density() (R 4.2.2).
x <- 25 + 3 * sin(0.31 * (1:40))
d <- density(x)
cat(sprintf("R_BW %.16g\n", bw.nrd0(x)))
cat(sprintf("R_GRID_ENDS (%.16g, %.16g)\n", d$x[1], d$x[512]))
for (i in c(1, 100, 256, 400, 512)) cat(sprintf("(%d, %.16g),\n", i, d$y[i]))
cat(sprintf("R_BW_CONSTANT (%.16g, %.16g)\n", bw.nrd0(c(2, 2, 2)), bw.nrd0(c(0, 0, 0))))

/* The rig-warp probe: what a plain C program needs to compute one channel's warp, to hold
 * `omniwarp bench rig` against. An OPENCV5 projector of 3840x2160 (or 1920x1080, the
 * intrinsics scaled; those of src/cli/bench/rig.rs, pose and surfaces too) is unprojected pixel
 * by pixel with Newton's method from the neighbouring pixel's answer to a residual below
 * 1e-10 px, its ray is hit against the wall (the cylinder's test includes the arc check with
 * atan2, the dome's the elevation check against the rim's sine, as omniwarp's do), and the content sampling
 * vector and wall point are written as float RGBA, rows in parallel (OpenMP).
 *
 *   cc -O3 -march=native -fopenmp -o rig_probe rig_probe.c -lm
 *   OMP_NUM_THREADS=2 ./rig_probe cylinder|dome|plane [3840x2160|1920x1080]
 *
 * Built for the machine it runs on (-march=native, which lets the compiler fuse multiplies and
 * adds) it is the hardware's pace; `omniwarp bench rig` builds and runs it so. Prints the best
 * of five runs (outputs allocated in each) in milliseconds and the lit pixel count. */
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static int W = 3840, H = 2160;
static double F[4] = {2400.0, 2400.0, 1919.5, 1079.5};
static const double K[5] = {-0.05, 0.01, 0.0005, -0.0003, -0.002}; /* k1 k2 p1 p2 k3 */
static const double POS[3] = {0.0, 0.3, 0.5};

/* Newton on the normalised plane; returns 0 when it does not converge. */
static int undistort(double u, double v, double *x, double *y) {
    double tx = (u - F[2]) / F[0], ty = (v - F[3]) / F[1];
    double k1 = K[0], k2 = K[1], p1 = K[2], p2 = K[3], k3 = K[4];
    for (int it = 0; it < 12; it++) {
        double X = *x, Y = *y, r2 = X * X + Y * Y, r4 = r2 * r2;
        double g = 1 + k1 * r2 + k2 * r4 + k3 * r4 * r2;
        double dg = k1 + 2 * k2 * r2 + 3 * k3 * r4;
        double ex = X * g + 2 * p1 * X * Y + p2 * (r2 + 2 * X * X) - tx;
        double ey = Y * g + p1 * (r2 + 2 * Y * Y) + 2 * p2 * X * Y - ty;
        if ((F[0] * ex) * (F[0] * ex) + (F[1] * ey) * (F[1] * ey) < 1e-20) return 1;
        double j00 = g + 2 * X * X * dg + 2 * p1 * Y + 6 * p2 * X;
        double j01 = 2 * X * Y * dg + 2 * p1 * X + 2 * p2 * Y;
        double j11 = g + 2 * Y * Y * dg + 6 * p1 * Y + 2 * p2 * X;
        double det = j00 * j11 - j01 * j01;
        *x -= (j11 * ex - j01 * ey) / det;
        *y -= (j00 * ey - j01 * ex) / det;
    }
    return 0;
}

enum Surface { CYLINDER, DOME, PLANE };

/* Ray parameter of the first wall hit, or -1. */
static double hit(enum Surface surface, const double d[3]) {
    const double *o = POS;
    if (surface == DOME) { /* radius 3 about the origin, zenith tilted 15 deg to -z, down to -30 deg */
        static const double tilt = 15.0 * M_PI / 180.0, lowest = -0.5; /* sin(-30 deg) */
        double b = d[0] * o[0] + d[1] * o[1] + d[2] * o[2];
        double c = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - 9.0, disc = b * b - c;
        if (disc < 0) return -1;
        double s = sqrt(disc), roots[2] = {-b - s, -b + s};
        for (int n = 0; n < 2; n++) {
            double t = roots[n];
            if (t <= 1e-9) continue;
            double px = o[0] + t * d[0], py = o[1] + t * d[1], pz = o[2] + t * d[2];
            double up = (px * 0.0 + py * cos(tilt) - pz * sin(tilt)) / 3.0;
            if (up >= lowest) return t;
        }
        return -1;
    }
    if (surface == CYLINDER) { /* radius 2 about +y through the origin, height -2..2, arc -180..180 */
        double a = d[0] * d[0] + d[2] * d[2], b = 2 * (d[0] * o[0] + d[2] * o[2]);
        double c = o[0] * o[0] + o[2] * o[2] - 4.0, disc = b * b - 4 * a * c;
        if (disc < 0 || a == 0) return -1;
        double s = sqrt(disc), roots[2] = {(-b - s) / (2 * a), (-b + s) / (2 * a)};
        for (int n = 0; n < 2; n++) {
            double t = roots[n];
            if (t <= 1e-9) continue;
            double px = o[0] + t * d[0], py = o[1] + t * d[1], pz = o[2] + t * d[2];
            double az = atan2(px, -pz) * 180.0 / M_PI;
            if (py >= -2 && py <= 2 && az >= -180 && az <= 180) return t;
        }
        return -1;
    }
    /* plane z = -3 facing +z, 12 x 8 m about (0, 0, -3) */
    if (d[2] == 0) return -1;
    double t = (-3.0 - o[2]) / d[2];
    if (t <= 1e-9) return -1;
    double px = o[0] + t * d[0], py = o[1] + t * d[1];
    return (fabs(px) <= 6 && fabs(py) <= 4) ? t : -1;
}

static long warp(enum Surface surface, float *map, float *wall) {
    long lit = 0;
#pragma omp parallel for schedule(dynamic, 8) reduction(+ : lit)
    for (int j = 0; j < H; j++) {
        double x = (0 - F[2]) / F[0], y = (j - F[3]) / F[1];
        for (int i = 0; i < W; i++) {
            float *m = map + 4 * ((size_t)j * W + i), *wp = wall + 4 * ((size_t)j * W + i);
            memset(m, 0, 16);
            memset(wp, 0, 16);
            if (!undistort(i, j, &x, &y)) {
                x = (i + 1 - F[2]) / F[0], y = (j - F[3]) / F[1];
                continue;
            }
            /* camera (x right, y down, z forward) to world: look-to -z, look-up +y */
            double n = sqrt(x * x + y * y + 1), d[3] = {x / n, -y / n, -1 / n};
            double t = hit(surface, d);
            if (t < 0) continue;
            double p[3] = {POS[0] + t * d[0], POS[1] + t * d[1], POS[2] + t * d[2]};
            double len = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]); /* eye at the origin */
            for (int c = 0; c < 3; c++) {
                m[c] = (float)(p[c] / len);
                wp[c] = (float)p[c];
            }
            m[3] = wp[3] = 1;
            lit++;
        }
    }
    return lit;
}

int main(int argc, char **argv) {
    const char *name = argc > 1 ? argv[1] : "plane";
    enum Surface surface = strcmp(name, "cylinder") == 0 ? CYLINDER
                           : strcmp(name, "dome") == 0   ? DOME
                                                         : PLANE;
    if (argc > 2 && sscanf(argv[2], "%dx%d", &W, &H) == 2 && W > 0 && H > 0) {
        double scale = W / 3840.0;
        F[0] *= scale;
        F[1] *= scale;
        F[2] = (F[2] + 0.5) * scale - 0.5;
        F[3] = (F[3] + 0.5) * scale - 0.5;
    }
    double best = 1e30;
    long lit = 0;
    for (int run = 0; run < 5; run++) {
        struct timespec a, b;
        clock_gettime(CLOCK_MONOTONIC, &a);
        /* Fresh outputs each run, as a warp computed on request has. */
        float *map = malloc(sizeof(float) * 4 * (size_t)W * H);
        float *wall = malloc(sizeof(float) * 4 * (size_t)W * H);
        lit = warp(surface, map, wall);
        clock_gettime(CLOCK_MONOTONIC, &b);
        free(map);
        free(wall);
        double ms = (b.tv_sec - a.tv_sec) * 1e3 + (b.tv_nsec - a.tv_nsec) / 1e6;
        if (ms < best) best = ms;
    }
    printf("probe %s %dx%d: %.1f ms, %ld lit, %d threads\n", name, W, H, best, lit,
           omp_get_max_threads());
    return 0;
}

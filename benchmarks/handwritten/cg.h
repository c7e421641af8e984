// Shared by the hand-written implicit loops (w2.cpp, w3.cpp): the conjugate gradient of SOFA's
// CGLinearSolver with tolerance = threshold = 0, i.e. from x = 0, at most `iterations` iterations,
// stopping early only when |b| = 0 or p.Ap = 0 exactly.
#pragma once

#include <cstdint>

// Solves A x = b. r holds b on entry (the residual on exit); p and q are work vectors of `size`.
// `product(p, q)` writes q = A p; `free_dof` (optional) zeroes the rows of projected-out DOFs
// (p stays 0 there because b is 0 there). Returns the iterations run.
template <class Product>
long conjugate_gradient(std::int64_t size, long iterations, const unsigned char* free_dof, double* r, double* p,
                        double* q, double* x, Product&& product) {
    double normb2 = 0.0;
    for (std::int64_t j = 0; j < size; ++j) {
        x[j] = 0.0;
        normb2 += r[j] * r[j];
    }
    double rho_previous = 0.0;
    long done = 0;
    for (long it = 1; normb2 != 0.0 && it <= iterations; ++it) {
        double rho = 0.0;
        for (std::int64_t j = 0; j < size; ++j) rho += r[j] * r[j];
        if (it == 1) {
            for (std::int64_t j = 0; j < size; ++j) p[j] = r[j];
        } else {
            const double beta = rho / rho_previous;
            for (std::int64_t j = 0; j < size; ++j) p[j] = r[j] + beta * p[j];
        }
        product(static_cast<const double*>(p), q);
        double den = 0.0;
        for (std::int64_t j = 0; j < size; ++j) {
            if (free_dof && !free_dof[j]) q[j] = 0.0;
            den += p[j] * q[j];
        }
        if (den == 0.0) break;
        const double alpha = rho / den;
        for (std::int64_t j = 0; j < size; ++j) {
            x[j] += alpha * p[j];
            r[j] -= alpha * q[j];
        }
        rho_previous = rho;
        done = it;
    }
    return done;
}

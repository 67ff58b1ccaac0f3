/* SPDX-License-Identifier: GPL-3.0-or-later
   Block-tridiagonal linear solve with 6 x 6 blocks (one block row per fiber node): the Newton
   systems of the implicit fiber step (physics/implicit_rod.h). Pure functions, no allocation
   inside the solve (the caller passes the storage), O(n) work.

   System: for k = 0..n-1
       L_k x_{k-1} + D_k x_k + U_k x_{k+1} = r_k      (L_0 and U_{n-1} unused)
   Blocks are row-major 6 x 6 (36 doubles). Block LU (Thomas algorithm) with partial pivoting
   inside each diagonal block:
       D'_0 = D_0,  D'_k = D_k - L_k G_{k-1},  G_k = D'_k^-1 U_k,  y_k = D'_k^-1 (r_k - L_k y_{k-1})
       x_{n-1} = y_{n-1},  x_k = y_k - G_k x_{k+1}.
   Stable without pivoting across blocks when the matrix is block diagonally dominant or
   symmetric positive definite (the mass-dominated Newton matrices of small time steps are both;
   large steps are made well conditioned by the symmetric diagonal scaling done by the caller).
   Reference: G.H. Golub, C.F. Van Loan, Matrix Computations, 4th ed. (2013), sec. 4.5.1. */
#ifndef FIBERFORM_PHYSICS_BLOCK_TRIDIAG_H
#define FIBERFORM_PHYSICS_BLOCK_TRIDIAG_H

#include <cmath>
#include <cstddef>

namespace fiberform::physics::blocktri {

constexpr int kB = 6;       // block size
constexpr int kBB = kB * kB;

// In-place LU with partial pivoting of an n x n row-major matrix; piv receives the row order.
// Returns false if a pivot is zero or not finite. (Also the dense capacitance solve of the
// Woodbury couplings in physics/implicit_rod.h.) N > 0 fixes the size at compile time (the 6 x 6
// blocks: unrolled loops, the same operations in the same order); N = 0 takes n.
template <int N = 0>
inline bool lu_factor(int n_, double *a, int *piv) {
  const int n = N > 0 ? N : n_;
  for (int i = 0; i < n; ++i) piv[i] = i;
  for (int c = 0; c < n; ++c) {
    int p = c;
    double best = std::fabs(a[c * n + c]);
    for (int r = c + 1; r < n; ++r) {
      const double v = std::fabs(a[r * n + c]);
      if (v > best) {
        best = v;
        p = r;
      }
    }
    if (!(best > 0.0) || !std::isfinite(best)) return false;
    if (p != c) {
      for (int k = 0; k < n; ++k) {
        const double t = a[c * n + k];
        a[c * n + k] = a[p * n + k];
        a[p * n + k] = t;
      }
      const int t = piv[c];
      piv[c] = piv[p];
      piv[p] = t;
    }
    const double inv = 1.0 / a[c * n + c];
    for (int r = c + 1; r < n; ++r) {
      const double l = a[r * n + c] * inv;
      a[r * n + c] = l;
      if (l != 0.0)
        for (int k = c + 1; k < n; ++k) a[r * n + k] -= l * a[c * n + k];
    }
  }
  return true;
}

// Solves (LU) Y = B for m right-hand sides, the columns of the row-major n x m B (Y in y, y != b;
// m = 1: one vector). Row operations on all columns at once; each entry sees the operations of a
// one-column solve in the same order. N, M > 0 fix n, m at compile time.
template <int N = 0, int M = 1>
inline void lu_solve_cols(int n_, const double *lu, const int *piv, const double *b, double *y) {
  const int n = N > 0 ? N : n_;
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < M; ++c) y[i * M + c] = b[piv[i] * M + c];
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < i; ++k) {
      const double l = lu[i * n + k];
      for (int c = 0; c < M; ++c) y[i * M + c] -= l * y[k * M + c];
    }
  for (int i = n - 1; i >= 0; --i) {
    for (int k = i + 1; k < n; ++k) {
      const double u = lu[i * n + k];
      for (int c = 0; c < M; ++c) y[i * M + c] -= u * y[k * M + c];
    }
    const double d = lu[i * n + i];
    for (int c = 0; c < M; ++c) y[i * M + c] /= d;
  }
}

// Solves (LU) y = b for one right-hand side (n values in b, the solution in y; y != b).
inline void lu_solve(int n, const double *lu, const int *piv, const double *b, double *y) {
  lu_solve_cols<0, 1>(n, lu, piv, b, y);
}

inline bool lu6(double *a, int *piv) { return lu_factor<kB>(kB, a, piv); }

// Solves (LU) x = b for one right-hand side (b overwritten by x).
inline void lu6_solve(const double *lu, const int *piv, double *b) {
  double y[kB];
  lu_solve_cols<kB, 1>(kB, lu, piv, b, y);
  for (int i = 0; i < kB; ++i) b[i] = y[i];
}

// Solves (LU) X = B for a 6 x 6 right-hand side B (row-major, overwritten by X).
inline void lu6_solve_mat(const double *lu, const int *piv, double *B) {
  double y[kBB];
  lu_solve_cols<kB, kB>(kB, lu, piv, B, y);
  for (int i = 0; i < kBB; ++i) B[i] = y[i];
}

// C -= A B (6 x 6)
inline void sub_mul6(double *C, const double *A, const double *B) {
  for (int i = 0; i < kB; ++i)
    for (int k = 0; k < kB; ++k) {
      const double a = A[i * kB + k];
      if (a == 0.0) continue;
      for (int j = 0; j < kB; ++j) C[i * kB + j] -= a * B[k * kB + j];
    }
}
// y -= A x (6 x 6 times 6)
inline void sub_mulv6(double *y, const double *A, const double *x) {
  for (int i = 0; i < kB; ++i) {
    double s = 0.0;
    for (int k = 0; k < kB; ++k) s += A[i * kB + k] * x[k];
    y[i] -= s;
  }
}

/* Factors the block-tridiagonal matrix in place. n block rows; D, L, U: n blocks each (36 doubles
   per block): D is overwritten by the LU factors of D'_k, U by G_k; L is kept. piv: 6 n ints.
   Returns false if a diagonal block became singular. */
inline bool factor(int n, double *D, const double *L, double *U, int *piv) {
  for (int k = 0; k < n; ++k) {
    double *Dk = D + static_cast<std::size_t>(k) * kBB;
    if (k > 0) sub_mul6(Dk, L + static_cast<std::size_t>(k) * kBB, U + static_cast<std::size_t>(k - 1) * kBB);
    int *pk = piv + static_cast<std::size_t>(k) * kB;
    if (!lu6(Dk, pk)) return false;
    if (k + 1 < n) lu6_solve_mat(Dk, pk, U + static_cast<std::size_t>(k) * kBB);  // G_k
  }
  return true;
}

/* Solves with the factors of factor(): rhs (6 n values) is overwritten by the solution. */
inline void solve_factored(int n, const double *D, const double *L, const double *U, const int *piv, double *rhs) {
  for (int k = 0; k < n; ++k) {
    double *rk = rhs + static_cast<std::size_t>(k) * kB;
    if (k > 0) sub_mulv6(rk, L + static_cast<std::size_t>(k) * kBB, rhs + static_cast<std::size_t>(k - 1) * kB);
    lu6_solve(D + static_cast<std::size_t>(k) * kBB, piv + static_cast<std::size_t>(k) * kB, rk);
  }
  for (int k = n - 2; k >= 0; --k)
    sub_mulv6(rhs + static_cast<std::size_t>(k) * kB, U + static_cast<std::size_t>(k) * kBB,
              rhs + static_cast<std::size_t>(k + 1) * kB);
}

/* Factors and solves in one call (D, U overwritten as in factor(); rhs by the solution). */
inline bool solve(int n, double *D, const double *L, double *U, double *rhs, int *piv) {
  if (!factor(n, D, L, U, piv)) return false;
  solve_factored(n, D, L, U, piv, rhs);
  return true;
}

}  // namespace fiberform::physics::blocktri

#endif

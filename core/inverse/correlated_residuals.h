// The covariance of a least-squares fit whose residuals are not independent.
//
// The Laplace covariance (identifiability.h) counts every observed depth point as an independent
// sample. Where the model itself is off (the grid, the time step, physics left out, a motion that
// no step size predicts) the points of one frame share one error and neighbouring frames share
// it too; the Laplace figure then shrinks with the number of pixels while the error does not. On
// an independent CalculiX capture the fitted friction coefficient came out 0.22 +- 0.001 where the
// truth was 0.3.
//
// The heteroskedasticity- and autocorrelation-consistent ("sandwich") covariance does not assume
// independence (Newey & West 1987): with frames as the clusters and a Bartlett window over
// neighbouring frames,
//   Cov = H^+ S H^+,   H = J^T J,
//   S = G / (G - 1) [sum_k g_k g_k^T + sum_{l=1..L} (1 - l / (L + 1)) sum_k (g_k g_{k+l}^T +
//   g_{k+l} g_k^T)],
// where g_k = J_k^T r_k is frame k's share of the gradient (J_k, r_k: its rows of the residual
// Jacobian and its residuals), G the number of frames and L the window in frames. As computed
// (LongRunCovariance) the g_k are centred, prewhitened by an AR(1) filter per variable before the
// sum and recoloured after it, and L is chosen from the data (AutomaticBandwidth): the plain sum
// above underestimates long-lived errors with the few frames a capture has. With independent
// residuals it agrees with the Laplace covariance on average; with G frames it is itself an
// estimate from G samples, so callers use it to widen the Laplace figure, never to narrow it.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace softid::inverse {

// The Bartlett window L [frames] by Andrews' (1991) plug-in rule: an AR(1) model rho_c fitted to
// each variable's series g_k[c] (innovation variance s_c^2), then
//   alpha = sum_c 4 rho_c^2 s_c^4 / ((1 - rho_c)^6 (1 + rho_c)^2) / sum_c s_c^4 / (1 - rho_c)^4,
//   L = floor(1.1447 (alpha G)^(1/3)),
// at most G - 1 (|rho_c| is capped at 0.97). Errors that persist over many frames get a wide
// window; independent ones about none. Newey and West's fixed rule, floor(4 (G / 100)^(2/9)) = 3
// for 31 frames, is narrower.
int AutomaticBandwidth(const std::vector<Eigen::VectorXd>& frame_gradients);

// g_k = J_k^T r_k per frame, for residuals stacked frame by frame: frame k owns
// `frame_sizes[k]` consecutive rows of `jacobian` and entries of `residuals`.
// @pre the sizes add up to jacobian.rows() == residuals.size()
std::vector<Eigen::VectorXd> FrameGradients(const Eigen::MatrixXd& jacobian,
                                            const Eigen::VectorXd& residuals,
                                            const std::vector<int>& frame_sizes);

// S (above) of a series g_1..g_G (each of p entries, G >= 1), for frames in time order, prewhitened
// (Andrews & Monahan 1992): the Bartlett sum runs over e_k = g_k - rho . g_{k-1}, rho each entry's
// AR(1) coefficient, with AutomaticBandwidth(e), and is recoloured by diag(1 / (1 - rho)). Without
// it the window misses most of a persistent drift: on errors correlated at 0.6 from frame to frame
// the sum caught under half of the true spread (CorrelatedResiduals tests). `bandwidth`, when
// given, receives the window used [frames].
Eigen::MatrixXd LongRunCovariance(const std::vector<Eigen::VectorXd>& series, int* bandwidth);

// H^+ S H^+ (above) for `h_pinv` = H^+ (p x p, finite) and the frames' gradients in time order;
// `bandwidth`, when given, receives the window used. Zero when there are fewer than 2 frames.
Eigen::MatrixXd CorrelatedResidualCovariance(const Eigen::MatrixXd& h_pinv,
                                             const std::vector<Eigen::VectorXd>& frame_gradients,
                                             int* bandwidth = nullptr);

}  // namespace softid::inverse

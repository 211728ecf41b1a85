#include "core/inverse/correlated_residuals.h"

#include <algorithm>
#include <cmath>

#include "core/common/check.h"

namespace softid::inverse {

// An AR(1) fit of a persistent drift can come out at 1; beyond this the rule's window explodes.
constexpr double kMaxAutocorrelation = 0.97;

namespace {

// Variable c's AR(1) coefficient in `series`, capped at +-kMaxAutocorrelation; NaN when the
// series is zero but for its last term (no variation to fit).
double Autocorrelation(const std::vector<Eigen::VectorXd>& series, int c) {
  double lagged = 0.0, previous_square = 0.0;
  for (size_t k = 1; k < series.size(); ++k) {
    lagged += series[k][c] * series[k - 1][c];
    previous_square += series[k - 1][c] * series[k - 1][c];
  }
  if (!(previous_square > 0.0)) return std::nan("");
  return std::clamp(lagged / previous_square, -kMaxAutocorrelation, kMaxAutocorrelation);
}

// Each variable's AR(1) coefficient, capped at +-kMaxAutocorrelation (0 without variation).
Eigen::VectorXd Autocorrelations(const std::vector<Eigen::VectorXd>& series) {
  const int p = static_cast<int>(series[0].size());
  Eigen::VectorXd rho(p);
  for (int c = 0; c < p; ++c) {
    const double value = Autocorrelation(series, c);
    rho[c] = std::isnan(value) ? 0.0 : value;
  }
  return rho;
}

}  // namespace

int AutomaticBandwidth(const std::vector<Eigen::VectorXd>& frame_gradients) {
  const int frames = static_cast<int>(frame_gradients.size());
  if (frames < 3) return 0;
  const int p = static_cast<int>(frame_gradients[0].size());
  double numerator = 0.0, denominator = 0.0;
  for (int c = 0; c < p; ++c) {
    const double rho = Autocorrelation(frame_gradients, c);
    if (std::isnan(rho)) continue;
    double innovation = 0.0;
    for (int k = 1; k < frames; ++k) {
      const double e = frame_gradients[k][c] - rho * frame_gradients[k - 1][c];
      innovation += e * e;
    }
    const double s4 = std::pow(innovation / (frames - 1), 2);
    numerator += 4.0 * rho * rho * s4 / (std::pow(1.0 - rho, 6) * std::pow(1.0 + rho, 2));
    denominator += s4 / std::pow(1.0 - rho, 4);
  }
  if (!(denominator > 0.0)) return 0;
  const double alpha = numerator / denominator;
  const int bandwidth = static_cast<int>(std::floor(1.1447 * std::cbrt(alpha * frames)));
  return std::min(bandwidth, frames - 1);
}

std::vector<Eigen::VectorXd> FrameGradients(const Eigen::MatrixXd& jacobian,
                                            const Eigen::VectorXd& residuals,
                                            const std::vector<int>& frame_sizes) {
  SOFTID_DEMAND(jacobian.rows() == residuals.size());
  std::vector<Eigen::VectorXd> out;
  out.reserve(frame_sizes.size());
  Eigen::Index row = 0;
  for (int size : frame_sizes) {
    SOFTID_DEMAND(size >= 0 && row + size <= jacobian.rows());
    out.push_back(jacobian.middleRows(row, size).transpose() * residuals.segment(row, size));
    row += size;
  }
  SOFTID_DEMAND(row == jacobian.rows());
  return out;
}

namespace {

// The Bartlett-weighted sum of the series' auto- and cross-covariances up to `bandwidth` lags.
Eigen::MatrixXd BartlettSum(const std::vector<Eigen::VectorXd>& series, int bandwidth) {
  const int p = static_cast<int>(series[0].size());
  const int n = static_cast<int>(series.size());
  Eigen::MatrixXd s = Eigen::MatrixXd::Zero(p, p);
  for (const Eigen::VectorXd& g : series) s += g * g.transpose();
  for (int lag = 1; lag <= bandwidth && lag < n; ++lag) {
    // The Bartlett weights keep the sum positive semi-definite.
    const double weight = 1.0 - lag / (bandwidth + 1.0);
    for (int k = 0; k + lag < n; ++k) {
      const Eigen::MatrixXd cross = series[k] * series[k + lag].transpose();
      s += weight * (cross + cross.transpose());
    }
  }
  return s;
}

}  // namespace

Eigen::MatrixXd LongRunCovariance(const std::vector<Eigen::VectorXd>& series, int* bandwidth) {
  const int n = static_cast<int>(series.size());
  if (bandwidth != nullptr) *bandwidth = 0;
  SOFTID_DEMAND(n > 0);
  const int p = static_cast<int>(series[0].size());
  for (const Eigen::VectorXd& g : series) SOFTID_DEMAND(g.size() == p);
  // Centred: at an optimum the frames' gradients sum to zero, and where the analysis runs a
  // little off one (a fit stopped early, the truth of a test) their mean is not an error.
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(p);
  for (const Eigen::VectorXd& g : series) mean += g / n;
  std::vector<Eigen::VectorXd> centred(n);
  for (int k = 0; k < n; ++k) centred[k] = series[k] - mean;
  if (n < 3) return BartlettSum(centred, 0) * (n > 1 ? n / (n - 1.0) : 1.0);
  // Prewhitening (Andrews & Monahan 1992): the window is chosen on, and summed over, what an
  // AR(1) per variable leaves; the sum is then recoloured by 1 / (1 - rho).
  const Eigen::VectorXd rho = Autocorrelations(centred);
  std::vector<Eigen::VectorXd> whitened(n - 1);
  for (int k = 1; k < n; ++k) whitened[k - 1] = centred[k] - rho.cwiseProduct(centred[k - 1]);
  const int window = AutomaticBandwidth(whitened);
  if (bandwidth != nullptr) *bandwidth = window;
  const Eigen::VectorXd recolour = (1.0 - rho.array()).inverse().matrix();
  const Eigen::MatrixXd s =
      recolour.asDiagonal() * BartlettSum(whitened, window) * recolour.asDiagonal();
  // Per frame (n - 1 whitened terms stand for n frames), with the clusters' small-sample factor.
  return s * (double(n) / (n - 1)) * (n / (n - 1.0));
}

Eigen::MatrixXd CorrelatedResidualCovariance(const Eigen::MatrixXd& h_pinv,
                                             const std::vector<Eigen::VectorXd>& frame_gradients,
                                             int* bandwidth) {
  SOFTID_DEMAND(h_pinv.rows() == h_pinv.cols());
  if (bandwidth != nullptr) *bandwidth = 0;
  const int p = static_cast<int>(h_pinv.rows());
  if (frame_gradients.size() < 2) return Eigen::MatrixXd::Zero(p, p);
  return h_pinv * LongRunCovariance(frame_gradients, bandwidth) * h_pinv;
}

}  // namespace softid::inverse

#include "halved_forward.hpp"

#include <cmath>
#include <limits>
#include <mutex>

#include "decimated_row.hpp"
#include "wavelet_detail.hpp"

namespace gear_damping_id {
namespace wavelet_detail {

HalvedForward::~HalvedForward() { release(); }

void HalvedForward::release() {
  std::lock_guard<std::mutex> lock(fftwPlannerMutex());
  for (int p = 0; p < 2; ++p) {
    if (plans_[p]) fftw_destroy_plan(plans_[p]);
    fftw_free(half_[p]);
    plans_[p] = nullptr;
    half_[p] = nullptr;
  }
  n_fft_ = 0;
}

bool HalvedForward::configure(long n_fft, FftPlanning planning) {
  if (n_fft == n_fft_ && n_fft_ > 0) return true;
  release();
  if (n_fft < 4 || n_fft % 2 != 0 || n_fft / 2 > std::numeric_limits<int>::max()) return false;
  const long M = n_fft / 2;
  const size_t doubles = 2 * static_cast<size_t>(M / 2 + 1);
  {
    std::lock_guard<std::mutex> lock(fftwPlannerMutex());
    for (int p = 0; p < 2; ++p) {
      half_[p] = fftw_alloc_real(doubles);
      if (!half_[p]) break;
      adviseHugePages(half_[p], sizeof(double) * doubles);
      plans_[p] =
          fftw_plan_dft_r2c_1d(static_cast<int>(M), half_[p],
                               reinterpret_cast<fftw_complex*>(half_[p]), fftwFlags(planning));
    }
  }
  if (!half_[0] || !half_[1] || !plans_[0] || !plans_[1]) {
    release();
    return false;
  }
  step_.resize(static_cast<size_t>(kTwiddleBlock));
  for (long j = 0; j < kTwiddleBlock; ++j) {
    const double t = -2.0 * kPi * static_cast<double>(j) / static_cast<double>(n_fft);
    step_[static_cast<size_t>(j)] = {std::cos(t), std::sin(t)};
  }
  n_fft_ = n_fft;
  return true;
}

void HalvedForward::transformHalf(int p, const double* y, long n, double mean) {
  const long M = n_fft_ / 2;
  double* h = half_[p];
  const long m = n > p ? std::min(M, (n - p + 1) / 2) : 0;  // samples p, p + 2, ... below n
  for (long j = 0; j < m; ++j) h[j] = y[2 * j + p] - mean;
  for (long j = m; j < M; ++j) h[j] = 0.0;
  fftw_execute(plans_[p]);
}

void HalvedForward::join(std::complex<double>* X) const {
  const long M = n_fft_ / 2, last = M / 2;
  const double* E = half_[0];
  const double* O = half_[1];
  double* x = reinterpret_cast<double*>(X);
  for (long b = 0; b <= last; b += kTwiddleBlock) {
    const double t = -2.0 * kPi * static_cast<double>(b) / static_cast<double>(n_fft_);
    const double cr = std::cos(t), ci = std::sin(t);
    const long e = std::min(last + 1, b + kTwiddleBlock);
    for (long k = b; k < e; ++k) {
      const std::complex<double> s = step_[static_cast<size_t>(k - b)];
      const double wr = cr * s.real() - ci * s.imag(), wi = cr * s.imag() + ci * s.real();
      const double er = E[2 * k], ei = E[2 * k + 1], orr = O[2 * k], oi = O[2 * k + 1];
      const double tr = wr * orr - wi * oi, ti = wr * oi + wi * orr;
      x[2 * (M - k)] = er - tr;
      x[2 * (M - k) + 1] = ti - ei;
      x[2 * k] = er + tr;
      x[2 * k + 1] = ei + ti;
    }
  }
}

}  // namespace wavelet_detail
}  // namespace gear_damping_id

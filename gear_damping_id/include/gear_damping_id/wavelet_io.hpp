// CSV writers of a wavelet validation (library gear_damping_id_io): the table of modes, the
// scalogram and the spectra. No ROS.
#pragma once

#include <iosfwd>
#include <string>

#include "gear_damping_id/wavelet_analysis.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_id {

/// Writes the table of modes (paper Table 2) as CSV with the header
///   frequency_hz,spectrum_frequency_hz,damping_ratio,integral_damping_ratio,sigma_per_s,r2,
///   t_start_s,t_end_s,omega0,peak_amplitude,noise_floor,free_decay,warning_codes,warnings
/// one row per mode (ascending frequency); NaN is written `nan`, free_decay `true`/`false`,
/// warning_codes the codes joined by ';', warnings the quoted warningText (any '"' doubled).
/// Ok, or InvalidArgument (an unusable result) / IoError (the file, named in the message).
gear_sim::Status writeModesCsv(const WaveletResult& result, std::ostream& out);
gear_sim::Status writeModesCsv(const WaveletResult& result, const std::string& path);

/// Writes the scalogram as CSV: a '#' comment line, then a numeric matrix M (comma-separated,
/// loadable with numpy.loadtxt(path, delimiter=',')): M[0][0] = M[0][1] = NaN, M[0][2:] = the
/// column times [s]; then one row per frequency: M[r][0] = frequency [Hz], M[r][1] = COI
/// half-width [s], M[r][2:] = |W|. Columns are block-averaged further so at most max_columns
/// remain. Ok, or InvalidArgument (empty scalogram) / IoError (with the path).
gear_sim::Status writeScalogramCsv(const WaveletResult& result, const std::string& path,
                                   long max_columns = 2000);
gear_sim::Status writeScalogramCsv(const WaveletResult& result, std::ostream& out,
                                   long max_columns = 2000);

/// Writes the spectra as CSV with header `kind,frequency_hz,power`: rows of kind `psd`
/// (WaveletResult::spectrum_power [unit^2/Hz], up to the grid's highest frequency) then
/// `scalogram` (time-averaged scalogram [unit^2]). Ok, or why not (as writeModesCsv).
gear_sim::Status writeSpectrumCsv(const WaveletResult& result, const std::string& path);
gear_sim::Status writeSpectrumCsv(const WaveletResult& result, std::ostream& out);

}  // namespace gear_damping_id

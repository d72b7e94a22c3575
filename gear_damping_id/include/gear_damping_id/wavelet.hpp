// Morlet-wavelet validation of damping, all of it: the CWT engine (morlet_cwt.hpp), the
// analysis of modes (wavelet_analysis.hpp) and the CSV writers (wavelet_io.hpp, library
// gear_damping_id_io). Include the part you need; this header includes the three.
#pragma once

#include "gear_damping_id/morlet_cwt.hpp"
#include "gear_damping_id/wavelet_analysis.hpp"
#include "gear_damping_id/wavelet_io.hpp"

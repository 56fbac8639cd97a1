#pragma once

// How a map forgets what moved (OccupancyDecay): plain values, part of the SDK.

namespace densemap {

/// How occupied evidence that is not seen again fades (OccupancyDecay).
struct DecayOptions {
  /// An occupied cell not hit for this long (seconds, 0 .. 10^6) starts to decay ...
  double after_s = 10.0;
  /// ... by one miss update every this many seconds (0.001 .. 10^6), until it is no longer
  /// occupied; then it is unknown.
  double period_s = 1.0;
  /// The engine's clock for scans: false, the time a scan is integrated (steady clock; a wrong
  /// stamp cannot age the map); true, the scan's own stamp (replays age the map as the
  /// recording did). Times are kept in whole milliseconds.
  bool use_stamps = false;
};

}  // namespace densemap

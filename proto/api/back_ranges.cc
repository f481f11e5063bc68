#include "proto/api/back_ranges.h"

#include <cstddef>

namespace radiosity::service {

int64_t BackRangeElements(const std::vector<int64_t>& ranges, int64_t elements) {
  if (elements < 0 || ranges.size() % 2 != 0) return -1;
  int64_t count = 0, previous_end = 0;
  for (size_t r = 0; r < ranges.size(); r += 2) {
    if (ranges[r] < previous_end || ranges[r + 1] <= ranges[r] || ranges[r + 1] > elements) {
      return -1;
    }
    count += ranges[r + 1] - ranges[r];
    previous_end = ranges[r + 1];
  }
  return count;
}

}  // namespace radiosity::service

// WatchJobResponse.back_ranges, shared by the server that writes them and the clients that read
// them: [begin, end) pairs of element indices, increasing and disjoint, of the elements that have
// a back side.
#ifndef RADIOSITY_PROTO_API_BACK_RANGES_H_
#define RADIOSITY_PROTO_API_BACK_RANGES_H_

#include <cstdint>
#include <vector>

namespace radiosity::service {

// The number of elements the ranges hold, or -1 when they are not such ranges of `elements`
// elements (odd length, empty, overlapping or unordered pairs, past the end).
int64_t BackRangeElements(const std::vector<int64_t>& ranges, int64_t elements);

}  // namespace radiosity::service

#endif  // RADIOSITY_PROTO_API_BACK_RANGES_H_

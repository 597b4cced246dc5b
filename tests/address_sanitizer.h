// Whether the suite is built with AddressSanitizer (`make sanitize`; g++ defines
// __SANITIZE_ADDRESS__, clang answers __has_feature). Under it every load and store is
// checked and a run of many steps is many times slower than in Release; suites that
// run long loops shorten them there and assert the long-time properties at full length
// in `make test`.
#pragma once

namespace dvm_tests {

#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif
#else
inline constexpr bool kAddressSanitizer = false;
#endif

}  // namespace dvm_tests

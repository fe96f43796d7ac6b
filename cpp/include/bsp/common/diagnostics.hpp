// Versions of the libraries the core was built against and runs with.
#pragma once
#include <map>
#include <string>

namespace bsp {
std::map<std::string, std::string> library_versions();
}

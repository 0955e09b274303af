// Where the tests find their fixtures, the CLI binary and (optionally) ../shared.
#pragma once

#include <string>

namespace rf::test {

std::string data_path(const std::string& relative);  // tests/data/<relative>
std::string cli_path();                               // the built `rayforge` binary
// ../shared/<relative> when it exists, "" otherwise (tests then GTEST_SKIP()).
std::string shared_path(const std::string& relative);
// A fresh, empty temporary directory for one test.
std::string temp_dir(const std::string& name);

}  // namespace rf::test

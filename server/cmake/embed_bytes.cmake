# cmake -DINPUT=file -DOUTPUT=file.cpp -DSYMBOL=name -P embed_bytes.cmake
# Writes a C++ source defining `std::span<const uint8_t> SYMBOL()` over the
# bytes of INPUT (the protocol schema's text, embedded in the recorder).
file(READ "${INPUT}" hex HEX)
string(LENGTH "${hex}" n)
math(EXPR size "${n} / 2")
string(REGEX REPLACE "([0-9a-f][0-9a-f])" "0x\\1," body "${hex}")
string(REGEX REPLACE "((0x[0-9a-f][0-9a-f],){16})" "\\1\n" body "${body}")
file(WRITE "${OUTPUT}.tmp"
  "// Generated from ${INPUT} by embed_bytes.cmake: do not edit.\n"
  "#include <cstdint>\n#include <span>\n\n"
  "namespace tactile {\n"
  "namespace { const uint8_t kBytes[${size}] = {\n${body}\n}; }\n"
  "std::span<const uint8_t> ${SYMBOL}() { return {kBytes, sizeof kBytes}; }\n"
  "}  // namespace tactile\n")
file(COPY_FILE "${OUTPUT}.tmp" "${OUTPUT}" ONLY_IF_DIFFERENT)

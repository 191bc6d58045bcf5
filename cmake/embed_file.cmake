# Writes a C++ source defining `const unsigned char NAME[]` (the bytes of IN, NUL
# terminated) and `const size_t NAME##Size` (without the NUL).
# cmake -DIN=file -DOUT=file.cc -DNAME=kSymbol -P embed_file.cmake
file(READ "${IN}" hex HEX)
string(LENGTH "${hex}" hex_len)
math(EXPR size "${hex_len} / 2")
string(REGEX REPLACE "([0-9a-f][0-9a-f])" "0x\\1," bytes "${hex}")
string(REGEX REPLACE "(0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,0x..,)" "\\1\n" bytes "${bytes}")
file(WRITE "${OUT}"
  "// Generated from ${IN} by cmake/embed_file.cmake; do not edit.\n"
  "#include <cstddef>\n"
  "extern const unsigned char ${NAME}[] = {\n${bytes}0x00};\n"
  "extern const size_t ${NAME}Size = ${size};\n")

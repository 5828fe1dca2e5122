# Writes OUT, a C++ file defining vox::kViewPage as the text of IN.
file(READ "${IN}" text)
set(delim "vox_page")
file(WRITE "${OUT}" "#include \"tools/view/page.h\"\nnamespace vox {\nconst char kViewPage[] = R\"${delim}(${text})${delim}\";\n}  // namespace vox\n")

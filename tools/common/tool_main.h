#pragma once
// A tool's entry point. A tool whose commands need OpenCV (btf-register, btf-synth) is built as a
// tool module, libbtf_tool_<tool>.so, which a small launcher executable loads with dlopen()
// (tools/common/launcher.cpp; docs/architecture.md, "Tool modules"); the other tools, and every
// tool in the sanitizer build, are ordinary executables. Its main.cpp, one file either way,
// declares its entry as
//   BTF_TOOL_MAIN(int argc, char** argv) { ... }
// which is `main`, or in a tool module (BTF_TOOL_MODULE defined) the module's one exported
// function btf_tool_main, called by the launcher with the launcher's own arguments.
// Depends on nothing: the launcher includes it too.

// The name the launcher looks up (dlsym) and its type.
#define BTF_TOOL_ENTRY "btf_tool_main"
using BtfToolEntry = int (*)(int argc, char** argv);

#ifdef BTF_TOOL_MODULE
#define BTF_TOOL_MAIN extern "C" __attribute__((visibility("default"))) int btf_tool_main
#else
#define BTF_TOOL_MAIN int main
#endif

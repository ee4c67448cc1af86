// bmtree C++ basic modules: the library's API level. Part of <bmtree/basic_module.h>, which
// includes it: include that one.
#ifndef BMTREE_API_H
#define BMTREE_API_H

/// The library's API level, for a module that must also build against older copies (#if
/// BMTREE_CPP_API >= 3): 2 added onCancel(), callId(), and made cancelled() and sleepFor() public;
/// 3 added emit() and bmtree::EventParam (events on /<BM>/BM_event), and cancels a call whose
/// caller's process is gone.
#define BMTREE_CPP_API 3

#endif  // BMTREE_API_H

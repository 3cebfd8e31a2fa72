#define_import_path displace::curved_bindings
#import displace::curved_prism::Prism

// displace-gpu's group 2 of a curved draw: the prisms the fragment walk
// reads (displace-bevy declares the same name in its material's group).
@group(2) @binding(0) var<storage, read> prisms: array<Prism>;

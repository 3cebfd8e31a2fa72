pub fn placeholder_render() {}

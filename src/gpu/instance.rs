//! The Vulkan instance: the loader, the instance and, when asked for and installed, the
//! Khronos validation layer with a messenger that keeps its warnings and errors. Destroyed
//! once, messenger first, when dropped.

use super::{GpuError, VkResultExt};
use ash::vk;
use std::ffi::{c_void, CStr};
use std::sync::Mutex;

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// The loader and an instance (Vulkan 1.2).
pub(crate) struct Instance {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    messenger: Option<Messenger>,
}

/// The validation layer's messenger and the messages it stored.
struct Messenger {
    loader: ash::ext::debug_utils::Instance,
    handle: vk::DebugUtilsMessengerEXT,
    /// Boxed: the callback holds its address for the messenger's lifetime.
    store: Box<Mutex<Vec<String>>>,
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _ty: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if !data.is_null() && !user.is_null() {
        let msg = unsafe { (*data).message_as_c_str() }.map(|m| m.to_string_lossy().to_string()).unwrap_or_default();
        let store = unsafe { &*(user as *const Mutex<Vec<String>>) };
        if let Ok(mut v) = store.lock() {
            v.push(format!("{severity:?}: {msg}"));
        }
    }
    vk::FALSE
}

impl Instance {
    /// Loads Vulkan and creates an instance, with the validation layer when `validation` is
    /// asked for and the layer is installed ([`Instance::validation`] tells which).
    pub fn new(validation: bool) -> Result<Instance, GpuError> {
        let entry = unsafe { ash::Entry::load() }.map_err(|e| GpuError::Loader(e.to_string()))?;
        let app = vk::ApplicationInfo::default().application_name(c"halftrace").api_version(vk::API_VERSION_1_2);
        let layers = unsafe { entry.enumerate_instance_layer_properties() }.vk("vkEnumerateInstanceLayerProperties")?;
        let have_layer = layers.iter().any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
        let use_layer = validation && have_layer;
        let layer_ptrs = if use_layer { vec![VALIDATION_LAYER.as_ptr()] } else { vec![] };
        let ext_ptrs = if use_layer { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
        let info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_ptrs)
            .enabled_extension_names(&ext_ptrs);
        let instance = unsafe { entry.create_instance(&info, None) }.vk("vkCreateInstance")?;
        // From here on, dropping `inst` destroys what exists.
        let mut inst = Instance { entry, instance, messenger: None };
        if use_layer {
            let loader = ash::ext::debug_utils::Instance::new(&inst.entry, &inst.instance);
            let store = Box::new(Mutex::new(Vec::<String>::new()));
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(debug_callback))
                .user_data(&*store as *const Mutex<Vec<String>> as *mut c_void);
            let handle =
                unsafe { loader.create_debug_utils_messenger(&info, None) }.vk("vkCreateDebugUtilsMessengerEXT")?;
            inst.messenger = Some(Messenger { loader, handle, store });
        }
        Ok(inst)
    }

    /// Whether the validation layer is on.
    pub fn validation(&self) -> bool {
        self.messenger.is_some()
    }

    /// The validation layer's warnings and errors so far.
    pub fn messages(&self) -> Vec<String> {
        match &self.messenger {
            Some(m) => m.store.lock().map(|v| v.clone()).unwrap_or_default(),
            None => Vec::new(),
        }
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        unsafe {
            if let Some(m) = self.messenger.take() {
                m.loader.destroy_debug_utils_messenger(m.handle, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

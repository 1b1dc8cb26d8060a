//! Keys of the list views: text entry (filters, values, paths), the parameter table and the
//! message inspector.

use ratatui::crossterm::event::{KeyCode, KeyEvent};

use super::{App, Level, ParamStatus, Request, SeriesKey, View};

impl App {
    /// Text entry: filters, a parameter value, a file path.
    pub(super) fn on_text(&mut self, key: KeyEvent) -> Vec<Request> {
        let is_filter = self.params.edit.is_none() && self.params.file_prompt.is_none();
        let view = self.view;
        let buf: &mut String = if let Some(e) = self.params.edit.as_mut() {
            e
        } else if let Some(p) = self.params.file_prompt.as_mut() {
            p
        } else if view == View::Params {
            &mut self.params.filter
        } else if view == View::Fleet {
            &mut self.fleet.filter
        } else {
            &mut self.messages.filter
        };
        match key.code {
            KeyCode::Char(c) => {
                buf.push(c);
                // The list under a filter changes: start from its top.
                if is_filter {
                    match view {
                        View::Params => self.params.selected = 0,
                        View::Fleet => self.fleet.cursor = None,
                        _ => self.messages.selected = 0,
                    }
                }
                Vec::new()
            }
            KeyCode::Backspace => {
                buf.pop();
                Vec::new()
            }
            KeyCode::Esc => {
                if is_filter {
                    buf.clear();
                }
                self.typing = false;
                self.params.edit = None;
                self.params.file_prompt = None;
                Vec::new()
            }
            KeyCode::Enter => {
                self.typing = false;
                if let Some(text) = self.params.edit.take() {
                    return self.submit_param(&text);
                }
                if let Some(path) = self.params.file_prompt.take() {
                    let path = path.trim().to_owned();
                    if path.is_empty() {
                        return Vec::new();
                    }
                    self.note(Level::Info, format!("reading {path}"));
                    return vec![Request::LoadGains(path)];
                }
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    /// Validates a typed value for the selected parameter and asks for the write.
    fn submit_param(&mut self, text: &str) -> Vec<Request> {
        let rows = self.params.filtered();
        let Some((_, (name, _))) = rows.get(self.params.selected) else {
            return Vec::new();
        };
        let name = name.clone();
        match text.trim().parse::<f32>() {
            Ok(v) if v.is_finite() => {
                self.params
                    .status
                    .insert(name.clone(), ParamStatus::Pending(v));
                vec![Request::ParamSet { name, value: v }]
            }
            _ => {
                let reason = format!("{text:?} is not a finite number");
                self.note(Level::Error, format!("{name}: {reason}"));
                self.params
                    .status
                    .insert(name, ParamStatus::NotSent(reason));
                Vec::new()
            }
        }
    }

    pub(super) fn on_params_key(&mut self, key: KeyEvent) -> Option<Vec<Request>> {
        let n = self.params.filtered().len();
        if self.replay && matches!(key.code, KeyCode::Enter | KeyCode::Char('f' | 'r')) {
            self.refuse_on_replay();
            return Some(Vec::new());
        }
        match key.code {
            KeyCode::Up => self.params.selected = self.params.selected.saturating_sub(1),
            KeyCode::Down => {
                self.params.selected = (self.params.selected + 1).min(n.saturating_sub(1));
            }
            KeyCode::PageUp => self.params.selected = self.params.selected.saturating_sub(10),
            KeyCode::PageDown => {
                self.params.selected = (self.params.selected + 10).min(n.saturating_sub(1));
            }
            KeyCode::Char('/') => {
                self.params.filter.clear();
                self.typing = true;
            }
            KeyCode::Esc => self.params.filter.clear(),
            KeyCode::Enter if n > 0 => {
                self.params.edit = Some(String::new());
                self.typing = true;
            }
            KeyCode::Char('f') => {
                self.params.file_prompt = Some("config/gains.param".into());
                self.typing = true;
            }
            KeyCode::Char('r') => {
                self.params.progress = Some(("download".into(), 0, 0));
                return Some(vec![Request::ParamsPull]);
            }
            _ => return None,
        }
        Some(Vec::new())
    }

    pub(super) fn on_messages_key(&mut self, key: KeyEvent) -> Option<Vec<Request>> {
        let m = &mut self.messages;
        match key.code {
            KeyCode::Up if m.in_fields => m.field = m.field.saturating_sub(1),
            KeyCode::Down if m.in_fields => {
                m.field = (m.field + 1).min(m.listed_fields.len().saturating_sub(1));
            }
            KeyCode::Up => {
                m.selected = m.selected.saturating_sub(1);
                m.field = 0;
            }
            KeyCode::Down => {
                m.selected = (m.selected + 1).min(m.listed.len().saturating_sub(1));
                m.field = 0;
            }
            KeyCode::Right => m.in_fields = true,
            KeyCode::Left => m.in_fields = false,
            KeyCode::Char('/') => {
                m.filter.clear();
                self.typing = true;
            }
            KeyCode::Esc => m.filter.clear(),
            KeyCode::Enter => {
                let (Some(&(system, component, message)), Some(path)) =
                    (m.listed.get(m.selected), m.listed_fields.get(m.field))
                else {
                    return Some(Vec::new());
                };
                let key = SeriesKey {
                    system,
                    component,
                    message,
                    path: path.clone(),
                };
                if m.charts.is_empty() {
                    m.charts.push(Vec::new());
                }
                let chart = m.charts.last_mut().unwrap_or_else(|| unreachable!());
                if !chart.contains(&key) {
                    chart.push(key);
                }
            }
            KeyCode::Char('n') => m.charts.push(Vec::new()),
            KeyCode::Delete | KeyCode::Backspace => {
                if let Some(chart) = m.charts.last_mut() {
                    chart.pop();
                    if chart.is_empty() {
                        m.charts.pop();
                    }
                }
            }
            _ => return None,
        }
        Some(Vec::new())
    }
}
